"""docs/python.md cannot rot: its Python code runs here, and what it prints must be the output
the page shows (the first ```text block after the code)."""
import contextlib
import io
import pathlib
import re

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[3]
DOC = ROOT / "docs" / "python.md"


def blocks(text, lang):
    return re.findall(rf"^```{lang}\n(.*?)^```$", text, flags=re.M | re.S)


def test_python_md_example_runs_and_prints_what_the_page_shows(tmp_path, monkeypatch):
    text = DOC.read_text()
    code = blocks(text, "python")
    shown = blocks(text, "text")
    assert code and shown, "docs/python.md lost its example or its output"
    monkeypatch.chdir(tmp_path)  # the example writes run.mcap into the working directory
    ns = {"__name__": "docs_python_md"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for block in code:
            exec(compile(block, str(DOC), "exec"), ns)  # noqa: S102 - the page's own code
    assert out.getvalue() == shown[0]
    # Beyond the printed digits: the replay is the logged observer to the f32 rounding of the
    # voltage it was given (the page says why), and it tracks.
    d = (ns["out"]["theta"] - ns["theta_logged"] + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(d)) < 2e-6
    assert np.sqrt(np.mean(ns["err_deg"][ns["tracking"]] ** 2)) < 0.5
