"""README's Python examples, run as written."""

import re
from pathlib import Path


def test_readmes_fitting_in_the_loop_lowers_its_loss(capsys):
    """README's example, run as written (float32): the loss after its ten Adam steps is at least 5% lower."""
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "Fitting in the loop" in b)
    exec(compile(block, "README.md", "exec"), {})
    losses = [float(v) for v in re.findall(r"loss ([0-9.e-]+)", capsys.readouterr().out)]
    assert len(losses) == 10 and losses[-1] <= 0.95 * losses[0], losses
