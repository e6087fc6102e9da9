"""The README's Python example runs and prints the seed chapter 000 panel values."""

import contextlib
import io
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.mark.slow
def test_readme_python_example_reproduces_seed_000():
    text = README.read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    buf = io.StringIO()
    scope = {}
    with contextlib.redirect_stdout(buf):
        exec(compile(code, "README.md", "exec"), scope)
    impulse, dv = (float(x) for x in buf.getvalue().split())
    assert impulse == pytest.approx(5946.847, rel=1e-6)  # the manual's panel, N s
    assert dv == pytest.approx(9.21, abs=5e-3)  # mph
    # head-on analytic gradient: d|dv1|/dv2 = (1 + eps) m2 / (m1 + m2)
    m1, m2 = 3183.475, 3496.531
    assert float(scope["dv_dspeed"]) == pytest.approx(1.1 * m2 / (m1 + m2), rel=1e-4)


def test_readme_set_up_commands_are_the_ci_commands():
    text = README.read_text()
    commands = re.findall(r"```bash\n(python3 -m venv[^\n]*)\n```", text)
    assert len(commands) == 2
    assert commands[0].endswith("ks-jax demo")
    test_cmd = commands[1].split("&&")[-1].strip()
    ci = (README.parent / ".ci" / "run").read_text()
    assert test_cmd in ci
