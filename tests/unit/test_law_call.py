"""A law called in its own thread (daemon/services/supervisor/law_call.py): its answer comes back; a
law that does not return in time is a fault and is not called again until it has; what it raises,
SystemExit included, is a fault named by its type."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from flagtrack.daemon.services.supervisor.law_call import LawCall


def test_an_answer_comes_back_with_the_time_it_took() -> None:
    calling = LawCall(lambda state: state * 2.0, timeout_s=5.0)
    answer = calling.call(2.0)
    assert (answer.value, answer.fault, calling.busy) == (4.0, "", False)
    assert 0 <= answer.took_s < 5.0
    calling.close()


@pytest.mark.parametrize(
    ("error", "named"),
    [
        (ZeroDivisionError("gain over zero"), "ZeroDivisionError: gain over zero"),
        (SystemExit(3), "SystemExit: 3"),
        (KeyboardInterrupt(), "KeyboardInterrupt"),
    ],  # fmt: skip
)
def test_whatever_a_law_raises_is_a_fault_named_by_its_type(error: BaseException, named: str) -> None:
    def law(state: object) -> float:
        raise error

    calling = LawCall(law, timeout_s=5.0)
    answer = calling.call(None)
    assert answer.value is None and answer.fault == f"raised {named}"
    assert calling.call(None).fault == f"raised {named}"  # the thread lives on
    calling.close()


def test_a_law_that_does_not_return_in_time_is_a_fault_and_is_not_called_again_until_it_has() -> None:
    release = threading.Event()
    calls: list[object] = []

    def law(state: object) -> float:
        calls.append(state)
        if state == "stuck":
            release.wait(30)
        return 1.0

    calling = LawCall(law, timeout_s=0.05)
    answer = calling.call("stuck")
    assert answer.fault == "did not return within 0.05 s" and answer.value is None
    assert calling.busy and calling.out_for_s() >= 0.05
    with pytest.raises(RuntimeError, match="not returned"):
        calling.call("next")
    assert calling.late(0.0) is None and calling.busy
    release.set()
    late = calling.late(10.0)
    assert late is not None and late.value == 1.0 and late.took_s >= 0.05
    assert not calling.busy and calling.out_for_s() == 0.0
    assert calling.call("next").value == 1.0
    assert calls == ["stuck", "next"]
    calling.close()


def test_what_the_law_returns_is_checked_in_its_thread_too() -> None:
    class Hangs:
        def __float__(self) -> float:
            threading.Event().wait()  # never returns
            return 0.0

    def check(value: object) -> tuple[object, str]:
        return float(value), ""  # type: ignore[arg-type]

    calling = LawCall(lambda state: Hangs(), timeout_s=0.05, check=check)
    assert calling.call(None).fault == "did not return within 0.05 s"  # the caller is not held
    calling.close()


def test_a_fault_says_the_line_of_the_laws_own_file_it_raised_through(tmp_path: Path) -> None:
    """`raised KeyError: 'cam0'` named no line, even with -vv: the law's deepest line in its own file
    does (not the library's below it)."""
    import importlib.util

    (tmp_path / "deep.py").write_text("import json\n\n\ndef law(state):\n    return json.loads(state)\n")
    spec = importlib.util.spec_from_file_location("deep", tmp_path / "deep.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    calling = LawCall(module.law, timeout_s=5.0)
    answer = calling.call("{not json")
    assert answer.fault.startswith("raised JSONDecodeError") and answer.where == "deep.py:5"
    good = calling.call("1.5")
    assert (good.value, good.fault, good.where) == (1.5, "", "")  # no fault, no line
    calling.close()
