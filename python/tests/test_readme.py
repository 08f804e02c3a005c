"""README.md's Python quick start runs as written (in a scratch directory where `data/` is
the repository's): the block under "## From Python" builds Puget Sound 1k, reads it, cuts a
coarse level, asks a scene and commits an edit."""
import os
import pathlib
import re

import numpy as np

import fmrh
from conftest import ROOT


def test_the_quick_start_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## From Python"):]
    block = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    (tmp_path / "data").symlink_to(ROOT / "data")
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(block, "README.md", "exec"), scope)
    assert scope["heights"].shape == (128, 256)
    assert scope["blocks"]
    with fmrh.open(tmp_path / "ps1k.fmrh") as t:
        assert np.all(t.read((10, 20, 4, 4)) == 0)
        exact = t.read()
    coarse, real = scope["coarse"], ~np.isnan(exact)
    real[20:24, 10:14] = False  # edited after the coarse read
    assert np.abs(coarse[real].astype(np.float64) - exact[real]).max() <= 5.0 + 1e-3
