"""Operator details of the collection app: waiting for devices, data loss, the finished episode in
review, clear errors for unknown objects and taken ports. Real env, real UDP receivers, real recorder."""

from __future__ import annotations

import socket

import h5py
import numpy as np
import pytest

from teleop.app.keys import ScriptedKeySource


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_episode_waits_for_device_data_then_announces_its_loss(tmp_path):
    """UDP tracker + glove with nobody sending: the episode waits (no step, clock still) until enter;
    then every step holds and the loss is announced once."""
    pytest.importorskip("defgrasp_env.recording")
    from teleop.app.devices import DeviceContext, build_controller
    from teleop.app.session import CollectionSession, SessionConfig, make_env_stack

    env, rec, marks = make_env_stack({"object": "cuboid"}, out_dir=tmp_path / "eps")
    ctx = DeviceContext(tracker_port=_free_udp_port(), glove_port=_free_udp_port())
    ctrl = build_controller("udp", "udp", ctx=ctx)
    msgs, lines = [], []
    keys = ScriptedKeySource([(6, "enter"), (10, "esc")])
    session = CollectionSession(env, ctrl, keys, recorder=rec, marks=marks,
                                config=SessionConfig(num_episodes=1, realtime=False, seed=0),
                                say=msgs.append, status=lines.append)
    report = session.run()
    text = "\n".join(msgs)
    assert "waiting for device data" in text and "starting the episode now (start key)" in text
    assert sum("DEVICE DATA LOST" in m for m in msgs) == 1 and report.data_losses == 1
    # polls 0..5 waited (no step); enter at 6 starts: steps at polls 6..9; Esc at 10 keeps them
    assert report.steps == 4
    (path,) = report.saved
    with h5py.File(path) as f:
        assert f.attrs["num_steps"] == 4
        np.testing.assert_allclose(f["steps/time"][()], 0.05 * np.arange(1, 5))
    assert any("DEVICE DATA LOST" in line for line in lines)


class _LoggingView:
    """The real 3D view, with a log of what the session asked it to show."""

    def __init__(self):
        from teleop.app.view import SceneView3D

        self.view = SceneView3D("127.0.0.1", 0)
        self.log = []

    def capture(self, env):
        return self.view.capture(env)

    def new_episode(self):
        self.view.new_episode()

    def update(self, frame, readouts):
        self.log.append((None if frame is None else frame[0], dict(readouts)))
        self.view.update(frame, readouts)

    def close(self):
        self.view.close()


def test_review_keeps_the_finished_episode_on_screen_with_its_result(tmp_path):
    pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    from teleop.app.devices import DeviceContext, build_controller
    from teleop.app.session import CollectionSession, SessionConfig, make_env_stack

    env, _, marks = make_env_stack({"object": "cuboid"}, out_dir=None)
    ctrl = build_controller("keyboard", None, ctx=DeviceContext(held_keys=lambda: {"r"}))  # r: flange up
    view = _LoggingView()
    keys = ScriptedKeySource([(5, "right"), (9, "esc")])
    session = CollectionSession(env, ctrl, keys, marks=marks, view=view,
                                config=SessionConfig(num_episodes=3, reset_time_s=60.0, realtime=False, view_hz=1000.0),
                                say=lambda m: None, status=lambda line: None)
    session.run()
    review = [(f, r) for f, r in view.log if r["phase"] == "review"]
    # the review opens with the finished episode's last state (flange raised by "r", not the reset
    # pose at 0.30 m) and draws no new frame after it: the reset scene is never shown in review
    assert len(review) >= 2 and review[0][0] is not None and all(f is None for f, _ in review[1:])
    assert review[0][0].flange_position[1] > 0.30 + 0.01
    shown = [f for f, _ in view.log if f is not None]
    assert review[-1][1]["last_episode"].startswith("kept: 5 steps")
    assert review[-1][1]["headline"].startswith("REVIEW - last episode kept: 5 steps")
    assert len(shown) >= 5


def test_unknown_object_lists_the_valid_names(capsys):
    from teleop.app.cli import main

    assert main(["--object", "banana", "--tracker", "keyboard", "--keys", "none", "--no-view", "--no-record"]) == 2
    err = capsys.readouterr().err
    assert "banana" in err and "cuboid" in err and "rope" in err and "random" in err


@pytest.mark.parametrize("view", ["3d", "2d"])
def test_view_port_clash_names_the_port_and_the_flag(capsys, view):
    if view == "3d":
        pytest.importorskip("viser", reason="needs the [viewer] extra (viser)")
    from teleop.app.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        rc = main(["--tracker", "keyboard", "--keys", "none", "--no-record", "--view", view, "--view-port", str(port)])
    err = capsys.readouterr().err
    assert rc == 2 and f"port {port}" in err and "--view-port" in err, err


def test_paced_loop_reports_when_it_cannot_keep_up():
    """A clock on which every call takes 40 ms: each pass of the loop overruns the 50 ms period; the
    session says BEHIND once per episode, counts the late steps and the achieved rate."""
    from teleop.app.devices import DeviceContext, build_controller
    from teleop.app.session import CollectionSession, SessionConfig, make_env_stack

    ticks = iter(np.arange(0.0, 1e4, 0.04))
    env, _, marks = make_env_stack({"object": "cuboid"}, out_dir=None)
    ctrl = build_controller("keyboard", None, ctx=DeviceContext(held_keys=set))
    msgs = []
    session = CollectionSession(env, ctrl, ScriptedKeySource([(12, "esc")]), marks=marks,
                                config=SessionConfig(num_episodes=1, realtime=True), clock=lambda: float(next(ticks)),
                                sleep=lambda s: None, say=msgs.append, status=lambda line: None)
    report = session.run()
    assert report.late_steps >= 3
    assert sum("BEHIND real time" in m for m in msgs) == 1, msgs
    assert report.loop_rate_hz["p50"] < 20.0
