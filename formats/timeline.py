"""Timeline files (issue 26): a result's `timeline` as an xarray Dataset with a `time` dimension, netCDF, CSV.

The Dataset has dims (link, time) and (link, step) (step i: from time i to time i + 1): one variable per
figure with its `units`, `in_outage` (1 inside an outage interval of the link, 0 outside; the intervals
themselves are in the attribute `outages`, JSON), coordinates time [s], link ("tx -> rx"), tx, rx, kind and
the receiver's position_x/y/z [m] over time. netCDF3 is written directly with the coverage maps' writer
(map_files._write_netcdf3: no HDF5, no xarray needed).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from owcsim.formats.map_files import _write_netcdf3
from owcsim.formats.optional import need
from owcsim.schemas.timeline import TimelineLinkPublic, TimelineResultPublic

if TYPE_CHECKING:  # pragma: no cover
    import xarray

__all__ = ["in_outage", "timeline_csv", "timeline_rows", "to_netcdf", "to_xarray", "write_timeline_files"]

#: The per-time figures of a timeline link and their units.
FIGURES = {
    "dc_gain": "1",
    "dc_gain_stderr": "1",
    "los_gain": "1",
    "received_power_w": "W",
    "rms_delay_spread_s": "s",
    "snr_db": "dB",
    "ber": "1",
    "max_bit_rate_bps": "bit/s",
}


def _values(link: TimelineLinkPublic, name: str, n: int) -> np.ndarray:
    raw = getattr(link, name) or [None] * n
    return np.array([np.nan if v is None else v for v in raw], float)


def in_outage(link: TimelineLinkPublic, times: list[float]) -> np.ndarray:
    """(T,) 1 where time t lies in one of the link's outage intervals (start <= t <= end), else 0."""
    t = np.asarray(times, float)
    out = np.zeros(len(t), np.int8)
    for o in link.outages:  # a link's few intervals
        end = np.inf if o.end_s is None else o.end_s
        out |= ((t >= o.start_s) & (t <= end)).astype(np.int8)
    return out


def _parts(tl: TimelineResultPublic) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """(data variables, coordinates, attributes) of `to_xarray`'s Dataset, without xarray."""
    n = len(tl.times_s)
    links = tl.links
    data: dict[str, Any] = {}
    for name, unit in FIGURES.items():
        data[name] = (("link", "time"), np.stack([_values(k, name, n) for k in links]), {"units": unit})
    if n > 1:  # (a netCDF3 dimension of size 0 would be the unlimited one)
        diff = np.stack([_values(k, "dc_gain_diff_stderr", n - 1) for k in links])
        data["dc_gain_diff_stderr"] = (
            ("link", "step"),
            diff,
            {"units": "1", "long_name": "standard error of dc_gain(time[i + 1]) - dc_gain(time[i])"},
        )
    data["in_outage"] = (
        ("link", "time"),
        np.stack([in_outage(k, tl.times_s) for k in links]),
        {"long_name": "1 inside an outage interval"},
    )
    pos = np.array([k.receiver_position for k in links], float).reshape(len(links), n, 3)
    coords: dict[str, Any] = {
        "time": (("time",), np.asarray(tl.times_s, float), {"units": "s"}),
        "link": (("link",), np.array([f"{k.tx} -> {k.rx}" for k in links]), {}),
        "tx": (("link",), np.array([k.tx for k in links]), {"long_name": "transmitter or group"}),
        "rx": (("link",), np.array([k.rx for k in links]), {"long_name": "receiver"}),
        "kind": (("link",), np.array([k.kind for k in links]), {}),
    }
    coords.update({f"position_{c}": (("link", "time"), pos[..., i], {"units": "m"}) for i, c in enumerate("xyz")})
    attrs = {
        "title": "owcsim timeline",
        "method": tl.method,
        "frames_source": tl.frames_source or "",
        "medium_in_time": tl.medium_in_time,
        "outage": tl.outage.model_dump_json() if tl.outage is not None else "",
        "outages": json.dumps({f"{k.tx} -> {k.rx}": [o.model_dump() for o in k.outages] for k in links}),
    }
    return data, coords, attrs


def to_xarray(tl: TimelineResultPublic) -> xarray.Dataset:
    """The timeline as an xarray Dataset with a `time` dimension (see the module docstring)."""
    xr = need("xarray", "a timeline Dataset")
    data, coords, attrs = _parts(tl)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def to_netcdf(tl: TimelineResultPublic, path: str | Path) -> Path:
    """Write the timeline as a netCDF3 file (the Dataset of `to_xarray`); returns the path."""
    path = Path(path)
    _write_netcdf3(*_parts(tl), path)
    return path


def timeline_rows(tl: TimelineResultPublic) -> str:
    """The CSV text: one row per link and time (time_s, tx, rx, kind, the figures, in_outage)."""
    n = len(tl.times_s)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["time_s", "tx", "rx", "kind", *FIGURES, "dc_gain_diff_stderr_to_next", "in_outage"])
    for k in tl.links:  # a few links x times: the table's rows
        cols = [_values(k, name, n) for name in FIGURES]
        diff = np.append(_values(k, "dc_gain_diff_stderr", max(n - 1, 0)), np.nan)
        out = in_outage(k, tl.times_s)
        for i, t in enumerate(tl.times_s):
            row = [repr(float(c[i])) if np.isfinite(c[i]) else "" for c in [*cols, diff]]
            w.writerow([repr(float(t)), k.tx, k.rx, k.kind, *row, int(out[i])])
    return buf.getvalue()


def timeline_csv(tl: TimelineResultPublic, path: str | Path) -> Path:
    """Write `timeline_rows` to `path`."""
    path = Path(path)
    path.write_text(timeline_rows(tl), encoding="utf-8")
    return path


def write_timeline_files(tl: TimelineResultPublic, out: str | Path, plot_format: str | None = "svg") -> list[Path]:
    """timeline.nc, timeline.csv and the timeline plot (timeline.svg written directly, or timeline.png by
    matplotlib; None: no plot) in the folder `out`; returns the paths."""
    from owcsim.formats.timeline_plot import timeline_figure, timeline_svg

    out = Path(out)
    paths = [to_netcdf(tl, out / "timeline.nc"), timeline_csv(tl, out / "timeline.csv")]
    if plot_format == "svg":
        paths.append(timeline_svg(tl, out / "timeline.svg"))
    elif plot_format is not None:
        fig = timeline_figure(tl)
        fig.savefig(out / "timeline.png", dpi=100)
        paths.append(out / "timeline.png")
    return paths
