"""`pmsm-sim datasheet --quick`: the HTML page renders in headless Chromium, sections and figures.

The page is opened from disk (file://) with the network off, a screenshot taken, and the PNG
decoded (Pillow): the page must have drawn text and figures down to the last section (ink far
down the page, the figures' own colours present), not a blank or cut page. The HTML's text must
hold every section title and one inline <svg> per figure.

Chromium: `chromium` (Debian) on PATH. Without it the test is skipped, unless
PMSM_REQUIRE_CHROMIUM=1 (scripts/test-all.sh sets it after installing Chromium), which makes a
missing or failing browser (or a missing Pillow) an error. Run as test_mcap.py (PMSM_SIM_BIN, or
a cargo build); needs Pillow (tests/data/requirements.txt)."""
import os
import shutil
import subprocess

import pytest

from test_mcap import sim_bin  # noqa: F401 - the binary fixture

TITLES = [
    "1. Angle error against load and speed",
    "2. Lowest closed-loop speed at rated torque",
    "3. Start-up from random rotor angles",
    "4. HFI magnet polarity from random rotor angles",
    "5. Self-commissioning: identification error and time",
    "6. Lock loss under parameter error (Monte Carlo)",
    "7. Cortex-M4F instructions per control tick",
]
WIDTH, HEIGHT = 1200, 7000
# The figures' colours (analysis/datasheet/plots.rs): first curve, second curve, "good" points.
FIGURE_COLOURS = [(0, 114, 178), (230, 159, 0), (0, 158, 115)]


def missing(what: str):
    """Fails when the test is required (scripts/test-all.sh), else skips."""
    if os.environ.get("PMSM_REQUIRE_CHROMIUM") == "1":
        pytest.fail(what)
    pytest.skip(what)


def chromium() -> str:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    missing("chromium is not on PATH (apt-get install -y chromium)")


def test_datasheet_html_renders_in_chromium(sim_bin, tmp_path):  # noqa: F811
    browser = chromium()
    try:
        from PIL import Image as image
    except ImportError:
        missing("Pillow is not installed (pip install -r tests/data/requirements.txt)")
    out = tmp_path / "ds"
    done = subprocess.run([sim_bin, "datasheet", "--quick", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    html = (out / "datasheet.html").read_text()
    for t in TITLES:
        assert f"<h2>{t}</h2>" in html, t
    figures = [line for line in (out / "datasheet.md").read_text().splitlines()
               if line.startswith("![")]
    assert len(figures) == 5  # the servo: no HFI figure
    assert html.count("<svg") == len(figures)

    png = tmp_path / "page.png"
    shot = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
         "--no-first-run", "--disable-extensions", f"--user-data-dir={tmp_path / 'profile'}",
         "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=<-loopback>",
         f"--screenshot={png}", f"--window-size={WIDTH},{HEIGHT}",
         (out / "datasheet.html").as_uri()],
        capture_output=True, text=True, timeout=120)
    assert shot.returncode == 0 and png.is_file(), shot.stderr[-2000:]
    img = image.open(png).convert("RGB")
    assert img.size == (WIDTH, HEIGHT), img.size
    pixels = img.load()
    # Ink: pixels clearly off white, per row (every 2nd pixel of every 2nd row, for speed).
    ink_rows = []
    ink = 0
    colours = {c: 0 for c in FIGURE_COLOURS}
    for y in range(0, HEIGHT, 2):
        row = 0
        for x in range(0, WIDTH, 2):
            p = pixels[x, y]
            if min(p) < 200:
                row += 1
            if p in colours:
                colours[p] += 1
        ink += row
        if row:
            ink_rows.append(y)
    share = ink / ((WIDTH // 2) * (HEIGHT // 2))
    assert share > 0.01, f"only {share:.4f} of the page is ink: blank?"
    # Drawn down the page: five 440 px figures and seven sections do not fit in 3500 px.
    assert ink_rows and ink_rows[-1] > 3500, f"the page ends at {ink_rows[-1] if ink_rows else 0} px"
    assert len(ink_rows) > 800, f"ink on only {len(ink_rows)} sampled rows"
    for c, n in colours.items():
        assert n > 30, f"figure colour {c} drawn on only {n} sampled pixels: figures not rendered?"
