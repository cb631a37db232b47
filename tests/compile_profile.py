"""Where the suite's time goes: an opt-in pytest plugin that sums JAX's tracing, lowering and XLA compile seconds
per test and per program (``jax.monitoring``'s events), in this process and each pytest-xdist worker, and prints
the largest at the end. Subprocesses a test starts (the CLI, Ray, 4 forced devices) are not seen: their time is
the test's time less what is listed.

    PYTHONPATH=tests .venv/bin/python -m pytest -q -n 2 --dist loadfile -p compile_profile --durations=0
"""

import collections
import json
import os
from pathlib import Path

import jax.monitoring
import pytest

STAGES = {"/jax/core/compile/jaxpr_trace_duration": "trace",
          "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
          "/jax/core/compile/backend_compile_duration": "compile"}
SHOWN = 25  # rows of each table

_now = {"test": "(collection)"}
_seconds = collections.Counter()  # (test, stage, program) -> seconds
_calls = collections.Counter()


def _record(event: str, seconds: float, **fields) -> None:
    if event in STAGES:
        key = (_now["test"], STAGES[event], fields.get("fun_name", "?"))
        _seconds[key] += seconds
        _calls[key] += 1


def _folder() -> Path:
    """Inside the run's folder that tests/conftest.py names for all workers and removes at the end."""
    return Path(os.environ["JAXMOCAP_TEST_CACHE"]) / "compile_profile"


def pytest_configure(config):
    jax.monitoring.register_event_duration_secs_listener(_record)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _now["test"] = item.nodeid
    yield
    _now["test"] = "(between tests)"


def pytest_sessionfinish(session):
    rows = [[*key, seconds, _calls[key]] for key, seconds in _seconds.items()]
    name = getattr(session.config, "workerinput", {}).get("workerid", "main")
    _folder().mkdir(exist_ok=True)
    (_folder() / f"{name}.json").write_text(json.dumps(rows))


def pytest_terminal_summary(terminalreporter, config):
    if hasattr(config, "workerinput"):
        return
    rows = [row for path in _folder().glob("*.json")
            for row in json.loads(path.read_text())]
    by_stage, by_test, by_program = collections.Counter(), collections.Counter(), collections.Counter()
    programs = collections.Counter()
    for test, stage, program, seconds, calls in rows:
        by_stage[stage] += seconds
        by_test[test] += seconds
        if stage == "compile":
            by_program[program] += seconds
            programs[program] += calls
    write = terminalreporter.write_line
    terminalreporter.section("JAX's compile stages (seconds, summed over the workers)")
    write("  ".join(f"{stage} {by_stage[stage]:.0f}" for stage in STAGES.values()))
    write("by test (trace + lower + compile):")
    for test, seconds in by_test.most_common(SHOWN):
        write(f"{seconds:8.1f}  {test}")
    write("XLA compile by program (seconds, compiles):")
    for program, seconds in by_program.most_common(SHOWN):
        write(f"{seconds:8.1f} {programs[program]:5d}  {program}")

