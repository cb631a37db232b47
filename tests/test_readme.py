"""README's Python examples, run as written."""

import os
import re
import subprocess
import sys
from pathlib import Path

from conftest import FAST_COMPILE_FLAG


def test_readmes_fitting_in_the_loop_lowers_its_loss():
    """README's example, run as written (float32) in a new Python process, as a user runs it (compiling at
    `conftest.FAST_COMPILE_FLAG`): the loss after its ten Adam steps is at least 5% lower."""
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "Fitting in the loop" in b)
    env = os.environ | {"XLA_FLAGS": f"{os.environ.get('XLA_FLAGS', '')} {FAST_COMPILE_FLAG}".strip()}
    proc = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    losses = [float(v) for v in re.findall(r"loss ([0-9.e-]+)", proc.stdout)]
    assert len(losses) == 10 and losses[-1] <= 0.95 * losses[0], losses
