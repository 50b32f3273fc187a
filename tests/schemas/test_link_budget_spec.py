"""schemas.link_budget: Komine's defaults, the one-of rules, bounds and located errors."""

import math

import pytest
from pydantic import ValidationError

from owcsim.schemas.base import SpecModel
from owcsim.schemas.errors import located
from owcsim.schemas.link_budget import IsiSplit, LinkBudgetSpec, LuminousOutputSpec


class _Doc(SpecModel):
    """A document that embeds both models, to check that errors are located by their path."""

    link_budget: LinkBudgetSpec
    photometry: list[LuminousOutputSpec] = []


def _errors(doc) -> list[tuple[str, str]]:
    with pytest.raises(ValidationError) as exc:
        _Doc.model_validate(doc)
    return located(exc.value.errors())


def test_defaults_are_komine_2004():
    spec = LinkBudgetSpec(bit_rate=10e6)
    assert (spec.responsivity, spec.background_current, spec.temperature, spec.open_loop_gain) == (
        0.53,
        5.1e-3,
        295.0,
        10.0,
    )
    assert spec.capacitance_per_area == pytest.approx(112e-12 / 1e-4)  # 112 pF/cm^2 in F/m^2
    assert (spec.channel_noise_factor, spec.transconductance) == (1.5, 30e-3)
    assert (spec.noise_bandwidth_factor_i2, spec.noise_bandwidth_factor_i3) == (0.562, 0.0868)
    assert spec.isi_split is IsiSplit.NRZ


def test_bandwidth_defaults_to_bit_rate():
    assert LinkBudgetSpec(bit_rate=10e6).noise_bandwidth == 10e6
    assert LinkBudgetSpec(bit_rate=10e6).bit_period == pytest.approx(1e-7)
    both = LinkBudgetSpec(bit_rate=10e6, bandwidth=7e6)
    assert (both.noise_bandwidth, both.bit_period) == (7e6, pytest.approx(1e-7))
    only_b = LinkBudgetSpec(bandwidth=7e6)
    assert (only_b.noise_bandwidth, only_b.bit_period) == (7e6, None)


def test_json_round_trip_and_descriptions_carry_units():
    spec = LinkBudgetSpec.model_validate({"bit_rate": 1e8, "responsivity": 0.4, "isi_split": "window"})
    assert LinkBudgetSpec.model_validate_json(spec.model_dump_json()) == spec
    for name, field in LinkBudgetSpec.model_fields.items():
        assert field.description, name
    units = {
        "responsivity": "[A/W]",
        "bit_rate": "[bit/s]",
        "bandwidth": "[Hz]",
        "background_current": "[A]",
        "temperature": "[K]",
        "capacitance_per_area": "[F/m^2]",
        "transconductance": "[S]",
    }
    for name, unit in units.items():
        assert unit in LinkBudgetSpec.model_fields[name].description


def test_needs_bit_rate_or_bandwidth():
    errs = _errors({"link_budget": {}})
    assert errs == [
        ("link_budget", "give `bit_rate` [bit/s] or `bandwidth` [Hz] (or both): the noise needs a bandwidth")
    ]


@pytest.mark.parametrize(
    "field,value",
    [
        ("responsivity", 0.0),
        ("responsivity", -0.5),
        ("responsivity", 11.0),
        ("bit_rate", 0.0),
        ("bit_rate", 1e14),
        ("bandwidth", -1.0),
        ("background_current", -1e-6),
        ("temperature", 0.0),
        ("open_loop_gain", 0.0),
        ("capacitance_per_area", 0.0),
        ("channel_noise_factor", -1.0),
        ("transconductance", 0.0),
        ("noise_bandwidth_factor_i2", 0.0),
        ("noise_bandwidth_factor_i3", 20.0),
        ("temperature", float("nan")),
        ("bit_rate", float("inf")),
        ("isi_split", "gaussian"),
    ],
)
def test_bad_value_is_located(field, value):
    errs = _errors({"link_budget": {"bit_rate": 1e7, field: value}})
    assert [loc for loc, _ in errs] == [f"link_budget.{field}"]


def test_unknown_field_is_located():
    errs = _errors({"link_budget": {"bit_rate": 1e7, "gain": 10}})
    assert errs[0][0] == "link_budget.gain" and "Extra inputs" in errs[0][1]


def test_zero_background_is_allowed():
    assert LinkBudgetSpec(bit_rate=1e7, background_current=0.0).background_current == 0.0


# --- photometry ----------------------------------------------------------------------------------


def test_photometry_one_of_and_conversions():
    m = 1.0
    by_flux = LuminousOutputSpec(luminous_flux=math.pi * 100.0)  # Lambertian: Phi = pi I0
    by_cd = LuminousOutputSpec(center_luminous_intensity=100.0)
    assert by_flux.center_intensity(m) == pytest.approx(100.0)
    assert by_cd.flux(m) == pytest.approx(math.pi * 100.0)
    assert by_cd.center_intensity(m) == 100.0 and by_flux.flux(m) == math.pi * 100.0
    # Komine's luminaire, 60 x 60 x 0.73 cd at semi-angle 70 deg (m = 0.646): 10031 lm.
    m70 = -math.log(2) / math.log(math.cos(math.radians(70)))
    assert LuminousOutputSpec(center_luminous_intensity=2628.0).flux(m70) == pytest.approx(10031.4, abs=0.1)


@pytest.mark.parametrize(
    "doc,msg",
    [
        ({}, "give exactly one of"),
        ({"luminous_flux": 1000.0, "center_luminous_intensity": 300.0}, "give exactly one of"),
    ],
)
def test_photometry_needs_exactly_one(doc, msg):
    errs = _errors({"link_budget": {"bit_rate": 1e7}, "photometry": [{"luminous_flux": 10.0}, doc]})
    assert errs[0][0] == "photometry.1" and msg in errs[0][1]


@pytest.mark.parametrize(
    "field,value",
    [
        ("luminous_flux", 0.0),
        ("luminous_flux", -5.0),
        ("luminous_flux", 1e9),
        ("center_luminous_intensity", float("nan")),
    ],
)
def test_photometry_bad_value_is_located(field, value):
    errs = _errors({"link_budget": {"bit_rate": 1e7}, "photometry": [{field: value}]})
    assert errs[0][0] == f"photometry.0.{field}"
