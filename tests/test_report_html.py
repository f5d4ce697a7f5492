"""The HTML report as a user sees it: rendered by a real headless browser (Debian's chromium),
offline, without script errors, every plot drawn; its decimation keeps every peak."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from verne_post.cli import main
from verne_post.report.series import envelope

EXAMPLES = Path(__file__).parent.parent / "examples"
# 5 joints x (position, velocity, acceleration), the feed, 5 margins, the time budget, 3 maps.
PLOTS_WITH_TIMING = 25


def chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    assert found, "the HTML report tests need a headless browser: apt-get install -y --no-install-recommends chromium"
    return found


def browse(page: Path, tmp_path: Path, *what: str) -> subprocess.CompletedProcess:
    """Run chromium headless on ``page`` with every network request sent to a dead proxy."""
    return subprocess.run(
        [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--proxy-server=127.0.0.1:9",
         f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1280,2600", "--virtual-time-budget=5000",
         *what, page.as_uri()],
        capture_output=True, text=True, timeout=180, check=False)


def report(tmp_path: Path, name: str, *extra: str) -> tuple[int, Path]:
    page = tmp_path / f"{Path(name).stem}.html"
    result = CliRunner().invoke(main, ["check", str(EXAMPLES / name), "--report", str(page), "-q", *extra])
    return result.exit_code, page


def assert_drawn(page: Path, tmp_path: Path, plots: int) -> str:
    dom = browse(page, tmp_path, "--dump-dom").stdout
    assert 'id="script-error"' not in dom, re.search(r'id="script-error"[^>]*>([^<]*)', dom).group(1)
    drawn = re.search(r'id="plots-drawn"[^>]*>(\d+)<', dom)
    assert drawn and int(drawn.group(1)) == plots
    return dom


def test_report_renders_offline_with_every_plot(tmp_path: Path) -> None:
    code, page = report(tmp_path, "nx_swarf_inch_crlf.cls")
    assert code == 0
    text = page.read_text(encoding="ascii")
    # Self-contained: nothing to fetch (no external scripts, styles, images or fonts).
    assert not re.search(r"""(src|href)\s*=\s*["'](?!#)""", text)
    assert "@import" not in text and "url(" not in text
    assert_drawn(page, tmp_path, PLOTS_WITH_TIMING)
    shot = tmp_path / "shot.png"
    browse(page, tmp_path, f"--screenshot={shot}")
    import matplotlib.image

    image = matplotlib.image.imread(shot)[..., :3]
    # The first joint plot sits in the top 1300 px; its canvas has coloured (not grey) pixels.
    top = image[:1300]
    coloured = np.ptp(top, axis=-1) > 0.25
    assert coloured.sum() > 500


def test_violations_link_to_their_cl_lines(tmp_path: Path) -> None:
    code, page = report(tmp_path, "nx_swarf_inch_crlf.cls", "--work-offset", "0", "0", "900")
    assert code == 3
    text = page.read_text(encoding="ascii")
    links = set(re.findall(r'<li class="violation"><span>violation</span> <a href="#cl-(\d+)"', text))
    assert links
    for line in links:
        assert f'id="cl-{line}"' in text
    source = (EXAMPLES / "nx_swarf_inch_crlf.cls").read_text().splitlines()
    line = min(links, key=int)
    excerpt = re.search(rf'id="cl-{line}"[^>]*><b>\s*{line}</b>  ([^<]*)</span>', text).group(1)
    assert excerpt.strip() == source[int(line) - 1].strip().replace("&", "&amp;")
    # No timed trajectory with violations: margins, budget and maps are still drawn.
    assert_drawn(page, tmp_path, 9)


def test_report_of_a_large_job_stays_small(tmp_path: Path) -> None:
    """The impeller (36,000 blocks) gives a page of the same order as a 900-block job."""
    code, page = report(tmp_path, "impeller_5axis.cls", "--no-timing")
    assert code == 0
    assert page.stat().st_size < 1_000_000
    assert_drawn(page, tmp_path, 9)


def test_envelope_keeps_every_peak() -> None:
    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0, 1000, 200_000))
    y = rng.normal(size=x.size)
    y[rng.integers(0, x.size, 40)] = rng.uniform(10, 20, 40)  # isolated spikes
    y[5000:5100] = np.nan  # a gap
    xs, ys = envelope(x, y, bins=300)
    assert len(xs) <= 600 and xs == sorted(xs)
    values = np.array([np.nan if v is None else v for v in ys])
    assert np.nanmax(values) == pytest.approx(np.nanmax(y), rel=1e-3)
    assert np.nanmin(values) == pytest.approx(np.nanmin(y), rel=1e-3)
    # Every spike is kept (each is the largest value of its bin): a point within a bin's width as high.
    kept, width = np.array(xs), (x[-1] - x[0]) / 300
    for k in np.flatnonzero(y > 10):
        near = np.abs(kept - x[k]) <= width
        assert np.nanmax(values[near]) >= y[k] * (1 - 1e-3)
