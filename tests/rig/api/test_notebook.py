"""examples/notebook.ipynb runs top to bottom in a real Jupyter kernel (nbclient, the
``python3`` kernel of ipykernel in this environment) against this checkout."""

from __future__ import annotations

import os
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from tests.support.paths import REPO as ROOT

NOTEBOOK = ROOT / "examples" / "notebook.ipynb"


def test_example_notebook_executes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # the kernel is a subprocess: it imports this checkout's rig, not another installed copy
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p))
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=120, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "\n".join(str(o.get("data", {}).get("text/plain", "")) for o in outputs)
    assert "<Campaign pair1-positions: 4 runs>" in text
    assert "lost_motion_arcmin_u" in text and "twist_arcmin" in text
    assert "'runout'" in text  # the diagnosis' verdict on the example campaign
    assert "'ok')" in text  # the simulated campaign passed its limit
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the plots are drawn
    # issue 21 item 20: the twist column is centred on the loop (not the encoder's ~6730')
    low, high = map(float, re.search(
        r"'twist_arcmin': \((-?[0-9.]+), (-?[0-9.]+)\)", text).groups())
    assert -10.0 < low < 0.0 < high < 10.0 and abs(low + high) < 0.5 * (high - low)
    # the run_finished event names the run that finished
    assert "('pos090-a100-r0', 'run pos090-a100-r0 completed')" in text
