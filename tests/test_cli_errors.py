"""Every CLI fails on a bad option in one line that names it, with exit status 2, before any work;
Ctrl-C keeps partial results; sim.evaluate's exit status says when missions failed."""
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

import drive_rover
from sim import evaluate, mission, wire

PROJECT = Path(__file__).resolve().parent.parent


def _fails(main, argv, option, capsys):
    """main(argv) must exit 2 with one stderr line naming ``option``; returns that line."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert option in err, err
    return err


@contextlib.contextmanager
def _busy_port():
    """A listening socket with SO_REUSEPORT, as eventlet.listen makes (so a second one would share it)."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        yield s.getsockname()[1]
    finally:
        s.close()


@pytest.fixture
def read_only_dir(tmp_path):
    """A folder nothing can be written into: read-only tmpfs (root), or a 0o500 folder (others)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    mounted = False
    if os.geteuid() == 0:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)],
                                 capture_output=True).returncode == 0
        if not mounted:
            pytest.skip("running as root without permission to mount a read-only tmpfs")
    else:
        ro.chmod(0o500)
    try:
        yield ro
    finally:
        if mounted:
            subprocess.run(["umount", str(ro)], capture_output=True)
        else:
            ro.chmod(0o700)


# ------------------------------------------------------------------ drive_rover.py
def test_drive_rover_busy_port_fails_instead_of_sharing_it(capsys):
    with _busy_port() as port:
        err = _fails(drive_rover.main, ["--port", str(port)], "--port", capsys)
    assert "in use" in err


@pytest.mark.parametrize("argv, option", [
    (["--port", "70000"], "--port"),
    (["--port", "http"], "--port"),
    (["--log-level", "LOUD"], "--log-level"),
    (["--dashboard", "--dashboard-port", "-1"], "--dashboard-port"),
])
def test_drive_rover_bad_values(argv, option, capsys):
    _fails(drive_rover.main, argv, option, capsys)


def test_drive_rover_image_folder_that_is_a_file_or_cannot_be_made(tmp_path, capsys):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    assert "is a file" in _fails(drive_rover.main, [str(a_file), "--port", "0"], "image_folder", capsys)
    assert "cannot create" in _fails(drive_rover.main, [str(a_file / "sub"), "--port", "0"], "image_folder", capsys)
    assert not (a_file.is_dir())  # nothing of the user's was touched


def test_drive_rover_read_only_disk(read_only_dir, capsys):
    err = _fails(drive_rover.main, [str(read_only_dir / "rec"), "--port", "0"], "image_folder", capsys)
    assert "read-only" in err or "permission denied" in err
    _fails(drive_rover.main, ["--save-map", str(read_only_dir / "m.npy"), "--port", "0"], "--save-map", capsys)


def test_drive_rover_busy_dashboard_port(capsys):
    with _busy_port() as port:
        _fails(drive_rover.main, ["--port", "0", "--dashboard", "--dashboard-port", str(port)],
               "--dashboard-port", capsys)


# ------------------------------------------------------------------ the twin's tools
@pytest.mark.parametrize("argv, option", [
    (["--seed", "-1"], "--seed"),
    (["--seed", "seven"], "--seed"),
    (["--time-limit", "0"], "--time-limit"),
    (["--log-level", "LOUD"], "--log-level"),
    (["--world", "nowhere.png"], "--world"),
])
def test_mission_bad_values(argv, option, capsys, tmp_path):
    _fails(mission.main, argv + ["--out", str(tmp_path / "o")], option, capsys)


def test_mission_bad_out(tmp_path, read_only_dir, capsys):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    _fails(mission.main, ["--out", str(a_file)], "--out", capsys)
    _fails(mission.main, ["--out", str(read_only_dir / "o")], "--out", capsys)
    _fails(mission.main, ["--out", str(tmp_path / "o"), "--record", str(a_file)], "--record", capsys)
    assert a_file.read_text() == "x"


@pytest.mark.parametrize("argv, option", [
    (["--seeds", "-3"], "--seeds"),
    (["--seeds", "1,x"], "--seeds"),
    (["--jobs", "0"], "--jobs"),
])
def test_evaluate_bad_values(argv, option, capsys, tmp_path):
    _fails(evaluate.main, argv + ["--out", str(tmp_path / "o")], option, capsys)


def test_evaluate_bad_out(tmp_path, capsys):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    _fails(evaluate.main, ["--out", str(a_file)], "--out", capsys)


@pytest.mark.parametrize("argv, option", [(["--port", "70000"], "--port"), (["--seed", "-2"], "--seed")])
def test_wire_bad_values(argv, option, capsys):
    _fails(wire.main, argv, option, capsys)


def test_help_names_the_real_command(capsys):
    for main, prog in ((mission.main, "python -m sim.mission"), (evaluate.main, "python -m sim.evaluate"),
                       (wire.main, "python -m sim.wire"), (drive_rover.main, "python drive_rover.py")):
        with pytest.raises(SystemExit):
            main(["--help"])
        assert capsys.readouterr().out.startswith(f"usage: {prog}")


# ------------------------------------------------------------------ failures and Ctrl-C
def test_evaluate_exits_non_zero_when_a_mission_fails(monkeypatch, tmp_path):
    def broken(*args, **kwargs):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(mission, "run_mission", broken)
    code = evaluate.main(["--seeds", "0", "--jobs", "1", "--world", "procedural:0", "--out", str(tmp_path),
                          "--no-progress"])
    assert code == 1
    res = json.loads((tmp_path / "evaluation.json").read_text())
    assert res["missions"][0]["end_reason"].startswith("error: RuntimeError")


class _CtrlCAfter:
    """Mission watcher that raises KeyboardInterrupt (what Ctrl-C does) after some frames."""

    def __init__(self, frames):
        self.left = frames

    def observe(self, client, event=None, force=False):
        self.left -= 1
        if self.left == 0:
            raise KeyboardInterrupt


def _mission_stopped_by(watcher, tmp_path):
    """Run a short mission that `watcher` interrupts after ~50 frames; its saved mission.json."""
    r = mission.run_mission(seed=1, world="procedural:0", time_limit=300, out=tmp_path, progress=False,
                            watchers=[watcher])
    saved = json.loads((tmp_path / "mission.json").read_text())
    assert r["end_reason"] == saved["end_reason"] == mission.INTERRUPTED
    assert 40 <= saved["frames"] <= 60
    return saved


def test_ctrl_c_in_a_mission_writes_the_partial_mission(tmp_path):
    saved = _mission_stopped_by(_CtrlCAfter(50), tmp_path)
    assert (tmp_path / "timeline.npz").exists()
    assert saved["time_limit_s"] == 300 and saved["code_version"] and saved["timing"] and saved["seed"] == 1
    import cv2

    png = cv2.imread(str(tmp_path / "mission.png"))
    assert png.shape[1] == 800 and png.shape[0] > 800  # the map plus a title with the figures and a legend


class _WrappedCtrlCAfter(_CtrlCAfter):
    """...raised the way numba passes it on: a SystemError caused by the KeyboardInterrupt."""

    def observe(self, client, event=None, force=False):
        try:
            super().observe(client, event, force)
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher returned a result with an exception set") from exc


def test_ctrl_c_wrapped_by_a_compiled_kernel_still_writes_the_partial_mission(tmp_path):
    _mission_stopped_by(_WrappedCtrlCAfter(50), tmp_path)


def test_a_mission_error_that_is_not_an_interrupt_still_propagates(tmp_path):
    class Broken(_CtrlCAfter):
        def observe(self, client, event=None, force=False):
            raise SystemError("a real bug")

    with pytest.raises(SystemError):
        mission.run_mission(seed=1, world="procedural:0", time_limit=300, out=tmp_path, progress=False,
                            watchers=[Broken(50)])


def test_ctrl_c_in_an_evaluation_keeps_finished_and_partial_missions(monkeypatch, tmp_path):
    real = mission.run_mission

    def second_seed_interrupted(seed, *args, **kwargs):
        if seed == 1:
            kwargs["watchers"] = list(kwargs.get("watchers", ())) + [_CtrlCAfter(30)]
        return real(seed, *args, **kwargs)

    monkeypatch.setattr(mission, "run_mission", second_seed_interrupted)
    code = evaluate.main(["--seeds", "0-3", "--jobs", "1", "--world", "procedural:0", "--time-limit", "2",
                          "--out", str(tmp_path), "--no-progress"])
    assert code == 130
    res = json.loads((tmp_path / "evaluation.json").read_text())
    assert [m["seed"] for m in res["missions"]] == [0, 1]  # seeds 2 and 3 never started
    assert res["missions"][1]["end_reason"] == mission.INTERRUPTED and res["meta"]["interrupted"]
    assert "Interrupted" in (tmp_path / "evaluation.md").read_text()


def _default_sigint():
    """A child started from a background shell inherits an ignored SIGINT; Ctrl-C must reach it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_sigint_to_a_running_mission_process(tmp_path):
    """The real thing: SIGINT to `python -m sim.mission` -> exit 130 and a partial mission.json."""
    rec = tmp_path / "rec"
    proc = subprocess.Popen([sys.executable, "-m", "sim.mission", "--world", "procedural:0", "--time-limit", "600",
                             "--out", str(tmp_path / "out"), "--record", str(rec), "--no-progress",
                             "--log-level", "WARNING"],
                            cwd=PROJECT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + 120
        while not list(rec.glob("IMG/*.jpg")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)  # the recording's first frame: the mission loop is running
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    saved = json.loads((tmp_path / "out" / "mission.json").read_text())
    assert saved["end_reason"] == "interrupted" and saved["frames"] > 0
