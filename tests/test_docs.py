"""The examples of the README and the tutorials run, and print what the pages say they print.

Convention (CONTRIBUTING.md, "Examples that run"): a fenced block whose info string carries
`title="runs in tests"` is executed: ```` ```sh ```` blocks by bash and ```` ```python ```` blocks by
the test interpreter, from the repository root, in page order (a later block may read what an earlier
one wrote). `.venv/bin/` in a command means this interpreter's bin folder; `scripts/run-example` runs
the command its script ends with (checked here). A block with `title="runs in tests with a server"`
runs the same way with an `owcsim serve` started on a free port of 127.0.0.1, its URL put in place of
`http://127.0.0.1:8000`; one titled "runs in tests (slow)" runs only with `-m slow` (with the page's
other blocks before it). A block titled "prints" right after a runnable block is what it prints on
stdout, compared as follows (the same document and seed give the same bits, so what is compared is
whether the page still shows what the code prints, not luck):

- the text between numbers must be the same, line by line;
- a figure with an error bar, `X ± E`: the page's and today's X within 2 combined standard errors
  (2 sqrt(E_page^2 + E_now^2); a change of random streams moves X by about one, so it is caught when the
  page copies a figure of other code, as the 2.422597e-06 of the old README was, 3.4 errors away), and E
  within a factor 2;
- a wall time (a number followed by the unit `s`, as in "in 0.17 s") is not compared;
- any other integer exactly, any other number within 1 % (derived figures: path loss, delay spread).
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [
    ROOT / "README.md",
    ROOT / "CONTRIBUTING.md",
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted((ROOT / "docs" / "tutorials").glob("*.md")),
]
FENCE = re.compile(
    r"^(?P<indent> *)(?P<fence>```+)(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)(?P=fence)\s*$", re.M | re.S
)
NUMBER = r"[-+]?(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?(?:[eE][-+]?\d+)?|nan"
TOKEN = re.compile(rf"(?P<x>{NUMBER})(?:\s*±\s*(?P<e>{NUMBER}))?")
SERVER_URL = "http://127.0.0.1:8000"


def blocks(page: Path) -> list[dict]:
    """The fenced blocks of a page: language, title, body."""
    out = []
    for m in FENCE.finditer(page.read_text()):
        info = m.group("info").strip()
        title = re.search(r'title="([^"]*)"', info)
        body = "\n".join(line[len(m.group("indent")) :] for line in m.group("body").splitlines())
        out.append(
            {
                "lang": info.split(" ")[0] if info else "",
                "title": title.group(1) if title else "",
                "body": body,
                "line": page.read_text()[: m.start()].count("\n") + 1,
            }
        )
    return out


def examples(page: Path) -> list[tuple[dict, dict | None]]:
    """(runnable block, its "prints" block or None) pairs of a page, in order."""
    bs = blocks(page)
    out = []
    for i, b in enumerate(bs):
        if b["title"].startswith("runs in tests"):
            nxt = bs[i + 1] if i + 1 < len(bs) and bs[i + 1]["title"] == "prints" else None
            out.append((b, nxt))
    return out


def _number(text: str) -> float:
    return float(text.replace(",", ""))


def compare(expected: str, actual: str) -> list[str]:
    """Differences between a "prints" block and the output, by the rules of the module docstring."""
    exp_lines, act_lines = expected.strip("\n").splitlines(), actual.strip("\n").splitlines()
    if len(exp_lines) != len(act_lines):
        return [f"{len(exp_lines)} lines on the page, {len(act_lines)} printed:\n{actual}"]
    problems = []
    for el, al in zip(exp_lines, act_lines):
        et, at = list(TOKEN.finditer(el)), list(TOKEN.finditer(al))
        texts = (TOKEN.sub("#", el), TOKEN.sub("#", al))
        if texts[0] != texts[1] or len(et) != len(at):
            problems.append(f"text differs:\n  page: {el}\n  now:  {al}")
            continue
        for me, ma in zip(et, at):
            x_e, x_a = _number(me["x"]), _number(ma["x"])
            after = el[me.end() : me.end() + 3]
            if math.isnan(x_e) and math.isnan(x_a):
                continue
            if me["e"] is not None and ma["e"] is not None:
                e_e, e_a = _number(me["e"]), _number(ma["e"])
                ok = abs(x_e - x_a) <= 2 * math.hypot(e_e, e_a) and 0.5 <= (e_a / e_e if e_e else 1.0) <= 2
            elif re.match(r" s\b", after):
                ok = True  # a wall time
            elif re.fullmatch(r"[-+]?[\d,]+", me["x"]):
                ok = x_e == x_a
            else:
                ok = abs(x_e - x_a) <= 0.01 * abs(x_e)
            if not ok:
                problems.append(f"{me.group(0)!r} on the page, {ma.group(0)!r} printed:\n  page: {el}\n  now:  {al}")
    return problems


def _run_example_command() -> str:
    """The command `scripts/run-example` ends with (after installing), with this interpreter's owcsim."""
    last = [ln for ln in (ROOT / "scripts" / "run-example").read_text().splitlines() if ln.startswith("exec ")]
    assert len(last) == 1 and last[0].startswith("exec .venv/bin/owcsim run "), last
    return last[0][len("exec ") :].replace('"$@"', "").strip()


_OUTPUTS: dict[str, str] = {}  # the same command on two pages (the quick start) runs once per session


def run_block(block: dict, server_url: str | None = None, timeout: float = 120) -> str:
    if server_url is None and block["body"] in _OUTPUTS:
        return _OUTPUTS[block["body"]]
    bindir = str(Path(sys.executable).parent) + "/"
    body = block["body"]
    if server_url:
        body = body.replace(SERVER_URL, server_url)
    env = {k: v for k, v in os.environ.items() if not k.startswith("OWCSIM_")}
    env["PATH"] = bindir + os.pathsep + env.get("PATH", "")
    env["MPLBACKEND"] = "Agg"
    if block["lang"] in ("sh", "bash", "console"):
        body = re.sub(r"^scripts/run-example\b", _run_example_command(), body, flags=re.M)
        body = body.replace(".venv/bin/", bindir)
        cmd = ["bash", "-euo", "pipefail", "-c", body]
    elif block["lang"] == "python":
        cmd = [sys.executable, "-c", body]
    else:
        raise AssertionError(f"line {block['line']}: cannot run a {block['lang']!r} block")
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"line {block['line']} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    if server_url is None:
        _OUTPUTS[block["body"]] = proc.stdout
    return proc.stdout


SLOW, SERVER = "runs in tests (slow)", "runs in tests with a server"


def _check_page(page: Path, kinds: set[str], server_url: str | None = None) -> None:
    """Run the page's runnable blocks whose title is in `kinds`, in page order; compare their output."""
    problems = []
    for block, prints in examples(page):
        if block["title"] not in kinds:
            continue
        out = run_block(block, server_url)
        if prints is not None:
            problems += [f"{page.name} line {prints['line']}: {p}" for p in compare(prints["body"], out)]
    assert not problems, "\n".join(problems)


def _pages(title: str) -> list[Path]:
    return [p for p in PAGES if any(b["title"] == title for b, _ in examples(p))]


@pytest.mark.parametrize("page", _pages("runs in tests"), ids=lambda p: str(p.relative_to(ROOT)))
def test_examples_run_and_print_what_the_page_says(page):
    _check_page(page, {"runs in tests"})


@pytest.mark.slow
@pytest.mark.parametrize("page", _pages(SLOW), ids=lambda p: str(p.relative_to(ROOT)))
def test_slow_examples_run_and_print_what_the_page_says(page):
    _check_page(page, {"runs in tests", SLOW})


@pytest.mark.slow  # a server start and two jobs: 6-16 s
@pytest.mark.parametrize("page", _pages(SERVER), ids=lambda p: str(p.relative_to(ROOT)))
def test_service_examples_against_a_real_server(page, tmp_path):
    from tests.server.helpers import ServerProcess

    with ServerProcess(tmp_path / "jobs.sqlite") as server:
        _check_page(page, {SERVER}, server.url)


def test_every_runnable_block_is_found_and_every_prints_block_follows_one():
    """The convention cannot silently match nothing: the README runs, each "prints" has its command."""
    assert examples(ROOT / "README.md"), "the README's quick start is not marked as runnable"
    for page in PAGES:
        bs = blocks(page)
        for i, b in enumerate(bs):
            if b["title"] == "prints":
                assert i > 0 and bs[i - 1]["title"].startswith("runs in tests"), f"{page.name} line {b['line']}"


def update(page: Path) -> None:
    """Write what each runnable block prints today into its "prints" block (`python tests/test_docs.py PAGE`).

    For a page whose output changed on purpose: read the diff before committing it.
    """
    text = page.read_text()
    if _pages(SERVER).count(page):
        import tempfile

        from tests.server.helpers import ServerProcess

        with tempfile.TemporaryDirectory() as tmp, ServerProcess(Path(tmp) / "jobs.sqlite") as server:
            outputs = [(run_block(b, server.url), p) for b, p in examples(page) if b["title"] == SERVER]
    else:
        outputs = [(run_block(b), p) for b, p in examples(page) if b["title"] in ("runs in tests", SLOW)]
    for out, prints in reversed(outputs):
        if prints is None:
            continue
        matches = [m for m in FENCE.finditer(text) if text[: m.start()].count("\n") + 1 == prints["line"]]
        m = matches[0]
        indent = m.group("indent")
        body = "".join(indent + line + "\n" for line in out.rstrip("\n").splitlines())
        text = text[: m.start("body")] + body + text[m.end("body") :]
    page.write_text(text)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    for name in sys.argv[1:]:
        update(Path(name).resolve())


# --- the comparison rules themselves --------------------------------------------------------------------------

LINE = "tx -> rx (backward): H0 = 2.426673e-06 ± 1.2e-09, path loss 56.15 dB, tau_rms = 10.048 ns"


def test_compare_accepts_the_same_output_and_a_wall_time_that_moved():
    summary = "200,000 paths in 0.17 s (paths); wrote out/a/result.json"
    assert compare(LINE + "\n" + summary, LINE + "\n" + summary.replace("0.17", "3.90")) == []


def test_compare_catches_the_old_readme_figure_and_other_drift():
    """The old README's 2.422597e-06 against today's 2.426673e-06 ± 1.2e-09 (3.4 errors) is caught."""
    old = LINE.replace("2.426673e-06", "2.422597e-06")
    assert compare(old, LINE)
    assert compare(LINE, LINE.replace("56.15", "57.15"))  # a derived figure 1.8 % off
    assert compare(LINE, LINE.replace("1.2e-09", "3.0e-09"))  # an error bar 2.5x larger
    assert compare("200,000 paths", "100,000 paths")  # counts are exact
    assert compare(LINE, LINE.replace("backward", "forward"))  # text is exact
    assert compare(LINE, LINE + "\nmore")  # so is the number of lines
    # within the rules: a figure one combined error away, a derived figure 0.5 % off
    assert compare(LINE, LINE.replace("2.426673e-06", "2.428370e-06").replace("10.048", "10.098")) == []
