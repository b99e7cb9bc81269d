"""docs/first-day.md, walked: every ``flagtrack`` command of its ``sh`` blocks runs, in the page's
order, in one folder, against a simulated twin of deploy/rig-single-pc.yaml (the same file with the
camera and the tunnel simulated), and ends as the page says (exit 0; 130 for those Ctrl-C ends).

What the twin cannot do as the page does is said in ``TWIN``: the page's commands are taken from the
page (tests/unit/test_first_day_commands.py checks them against the real parsers), so a command the
page changes is run as changed, and one the page drops is no longer run.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from tests.fakes.helpers import wait_until
from tests.fakes.rig import TWIN as LIGHT_TWIN
from tests.unit.test_first_day_commands import COMMANDS, PENDING, SYSTEM, DocCommand

REPO = Path(__file__).resolve().parents[2]
FLAGTRACK = [sys.executable, "-m", "flagtrack.daemon"]


def write_twin(folder: Path) -> None:
    """deploy/rig-single-pc.yaml with the hardware simulated: the camera is the digital twin (its flag in
    pixels where the tracker looks: the twin's flag is not seen through a calibrated camera; the light
    twin of the other end-to-end tests, which a machine shared with the tests still makes in real time), the tunnel
    runs on a pseudo-terminal with a faster ramp, the plan has two points, and the view goes nowhere
    (the tests' machine has no display, and a file of the view would only cost time)."""
    rig = yaml.safe_load((REPO / "deploy" / "rig-single-pc.yaml").read_text())
    # the light twin at half speed, lagging rather than skipping: in one process with the tracker and the
    # recorder, on a CI host running another rig beside it, it fell 1 s behind at full speed
    twin = {"root_px": [150, 240], **LIGHT_TWIN, "time_scale": 0.5, "max_lag_s": 10.0}
    rig["camera"] = {"id": rig["camera"]["id"], "adapter": "simulated", "simulated": twin}
    rig["tracker"] = {**rig["tracker"], "root": [150, 240], "length": 300}
    safety = {**rig["tunnel"]["safety"], "max_ramp_mps2": 2.0}
    rig["tunnel"] = {"driver": "simulated", "safety": safety, "sim": {"tau_s": 0.2, "ramp_mps2": 3.0}}
    rig["viewer"] = {"sink": "none"}
    rig["supervisor"]["sweep"] = {**rig["supervisor"]["sweep"], "range": {"start": 4.0, "stop": 6.0, "step": 2.0}}
    rig["supervisor"]["sweep"].update(branches=["up"], settle_s=1, record_s=1.5)
    (folder / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))


def simulated_board(folder: Path) -> None:
    """The twin shows a flag, not a screen: the board's recording is the simulated one of the same size."""
    run(folder, ["simulate", "sim", "--checkerboard", "--corners", "9x6", "--square-mm", "20"])
    (folder / "recordings").mkdir(exist_ok=True)
    shutil.move(folder / "sim" / "checkerboard.raw", folder / "recordings" / "board.raw")


def simulated_flag(folder: Path) -> None:
    """The flag's recording for ``geometry`` is a simulated recording of a flapping flag of the same
    sensor size (the twin, at its own ``speed_mps`` in ``up``, would cost the test seconds of real time)."""
    run(folder, ["simulate", "simflag", "--duration", "0.5"])
    (folder / "recordings").mkdir(exist_ok=True)
    shutil.move(folder / "simflag" / "sim_00000.raw", folder / "recordings" / "flag.raw")


TWIN: dict[str, Callable[[Path], None]] = {
    "cp deploy/rig-single-pc.yaml rig.yaml": write_twin,
    "flagtrack up -c rig.yaml --record board": simulated_board,
    "flagtrack up -c rig.yaml --record flag": simulated_flag,
}
"""The page's lines the simulated rig does otherwise (each function's docstring says how)."""

UNTIL_CTRL_C: dict[str, Callable[[Path, list[str]], object]] = {
    "flagtrack aim -c rig.yaml": lambda folder, out: any(line.startswith("t ") for line in out),
    "flagtrack up -c rig.yaml --record test1": lambda folder, out: (
        (folder / "recordings" / "test1.raw").exists()
        and (folder / "recordings" / "test1.raw").stat().st_size > TEST_RECORDING_BYTES
    ),
}
"""Commands that run until Ctrl-C, and what shows they are at work (then they get SIGINT)."""
TEST_RECORDING_BYTES = 200_000
"""The test recording is long enough for the page's next steps (a few seconds of the still flag)."""


def run(folder: Path, argv: list[str], timeout_s: float = 600) -> subprocess.CompletedProcess:
    done = subprocess.run([*FLAGTRACK, *argv], cwd=folder, capture_output=True, text=True, timeout=timeout_s)
    assert done.returncode == 0, f"flagtrack {' '.join(argv)}: exit {done.returncode}\n{done.stderr[-3000:]}"
    return done


def run_until_ctrl_c(folder: Path, argv: list[str], at_work: Callable[[Path, list[str]], object]) -> None:
    command = f"flagtrack {' '.join(argv)}"
    out: list[str] = []  # the lines of both streams (aim's lines per second go to stderr)
    with subprocess.Popen(
        [*FLAGTRACK, *argv], cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as proc:
        readers = [threading.Thread(target=out.extend, args=(stream,)) for stream in (proc.stdout, proc.stderr)]
        for reader in readers:
            reader.start()
        try:
            wait_until(lambda: at_work(folder, out) or proc.poll() is not None, 600, f"{command} at work")
            assert proc.poll() is None, f"{command} ended by itself: {''.join(out)[-3000:]}"
            proc.send_signal(signal.SIGINT)
            code = proc.wait(120)
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            for reader in readers:
                reader.join(30)
    assert code in (0, 130), f"{command}: exit {code}\n{''.join(out)[-3000:]}"


def with_placeholders(command: DocCommand, folder: Path) -> list[str]:
    """The command's words after ``flagtrack``, ``RUN`` being the one run folder the sweep made."""
    words = command.argv[1:]
    if any("RUN" in word for word in words):
        runs = [p.name for p in (folder / "runs").iterdir() if p.is_dir()]
        assert len(runs) == 1, runs
        words = [word.replace("RUN", runs[0]) for word in words]
    return words


def walk(folder: Path, commands: list[DocCommand]) -> list[tuple[DocCommand, str]]:
    """Run the page's lines in ``folder``; the lines not run, with the reason."""
    not_run = []
    for command in commands:
        if command.line in TWIN:
            TWIN[command.line](folder)
        elif command.program != "flagtrack":
            not_run.append((command, SYSTEM[command.program]))
        elif command.argv[1] in PENDING:
            not_run.append((command, PENDING[command.argv[1]]))
        elif command.line in UNTIL_CTRL_C:
            run_until_ctrl_c(folder, with_placeholders(command, folder), UNTIL_CTRL_C[command.line])
        else:
            run(folder, with_placeholders(command, folder))
    return not_run


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_every_command_of_the_first_day_runs_on_the_simulated_rig(tmp_path: Path) -> None:
    not_run = walk(tmp_path, COMMANDS)
    ran = [c for c in COMMANDS if c.program == "flagtrack" and c not in [n for n, _ in not_run]]
    assert len(ran) >= 15 and all(c.program in SYSTEM or c.argv[1] in PENDING for c, _ in not_run)
    assert (tmp_path / "cal.yaml").is_file() and (tmp_path / "aim.png").is_file()
    assert (tmp_path / "recordings" / "test1.raw").stat().st_size > TEST_RECORDING_BYTES
    assert (tmp_path / "test1.h5").is_file()
    (run_dir,) = (tmp_path / "runs").iterdir()
    assert (run_dir / "summary.csv").is_file() and (run_dir / "README.txt").is_file()
    listed = run(tmp_path, ["runs", "list", "runs", "--json"]).stdout
    assert '"finished"' in listed


def test_the_twin_entries_are_lines_of_the_page() -> None:
    """No stale substitute: each line the twin does otherwise is still on the page."""
    lines = {c.line for c in COMMANDS}
    assert set(TWIN) <= lines and set(UNTIL_CTRL_C) <= lines
