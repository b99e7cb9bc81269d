"""The ``flagtrack`` command line: the parser built for one command, ``--version``, start-up imports."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from flagtrack.daemon import cli


def _choices(parser) -> set[str]:
    return set(next(a for a in parser._actions if a.dest == "command").choices)


def test_a_named_command_gets_only_its_own_parser() -> None:
    everything = _choices(cli.build_parser())
    assert {"reconstruct", "up", "bench", "tracker", "demo"} <= everything
    assert _choices(cli.build_parser("reconstruct")) == {"reconstruct"}
    assert cli._named_command(["-v", "reconstruct", "rec.raw", "-o", "out.h5"]) == "reconstruct"
    assert cli._named_command(["bench", "reconstruct"]) == "bench"
    assert cli._named_command(["recon"]) is None  # not a command: the full parser names the choices
    assert cli._named_command(["--version"]) is None


def test_an_unknown_command_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["recon", "x"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'recon'" in err and "'reconstruct'" in err and "'up'" in err


def test_a_named_command_parses_as_with_the_full_parser() -> None:
    argv = ["-v", "reconstruct", "rec.raw", "-o", "out.h5", "--tau", "2e-4", "--joints", "12"]
    one, full = cli.build_parser("reconstruct").parse_args(argv[1:]), cli.build_parser().parse_args(argv[1:])
    assert vars(one) == vars(full)
    assert one.joints == 12 and one.tau == pytest.approx(2e-4)


def test_version_prints_on_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    from flagtrack.daemon import __version__

    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out == f"flagtrack {__version__}\n"
    assert __version__ != "0.0.0+unknown"  # the installed package's version is found


def test_command_start_up_leaves_yaml_and_package_metadata_unimported() -> None:
    """``import yaml`` (~20 ms) and ``importlib.metadata`` (~30 ms) wait until a command needs them."""
    code = (
        "import sys; from flagtrack.daemon import cli; cli.build_parser('reconstruct'); "
        "from flagtrack.daemon.commands import reconstruct; "
        "print(sorted({'yaml', 'importlib.metadata'} & set(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_service_process_starts_without_rerun_or_scipy_unless_it_runs_them(tmp_path) -> None:
    """Every service reads the whole rig config: the viewer's rerun and the supervisor's SciPy (~1 s
    together) are imported only by the processes that run a viewer or a supervisor."""
    rig = tmp_path / "rig.yaml"
    rig.write_text("rig: lab\ntracker: {root: [100, 240], length: 200}\n")
    heavy = "{'rerun', 'scipy.signal', 'scipy.optimize'}"
    code = (
        "import sys; from flagtrack.daemon.rig.config import load_rig; from flagtrack.daemon.rig import run; "
        f"load_rig({str(rig)!r}, services=('tracker',)); print(sorted({heavy} & set(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    code = "import sys; from flagtrack.daemon.services.viewer import ViewerService; print('rerun' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"  # what needs rerun still comes from the package, when asked for


def test_kernels_status_names_the_cache_folder_and_says_when_there_is_no_build(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.setenv("FLAGTRACK_KERNEL_CACHE", str(tmp_path))
    assert cli.main(["kernels", "status", "--json"]) == 0
    status = json.loads(capsys.readouterr().out)
    assert status["usable"] is False and status["exports"] == 0
    assert status["folder"].startswith(str(tmp_path))
