"""defgrasp-teleop collection app: keys, episode flow, devices, live view, sessions, Ctrl-C safety."""

import json
import os
import pathlib
import signal
import urllib.request

import h5py
import numpy as np
import pytest

from teleop.app.control import Effect, EpisodeControl, Phase
from teleop.app.keys import (
    DEFAULT_RECORD_KEYS, KEY_SOURCES, NullKeySource, RecordCommand, ScriptedKeySource, TerminalKeySource,
    command_for_key, commands_for_keys, decode_terminal_keys, make_key_source,
)

DATA = pathlib.Path(__file__).parent / "data"
STREAM = "human_pick_cuboid"
R, L, S, ESC = RecordCommand.END_EPISODE, RecordCommand.RERECORD, RecordCommand.MARK_SUCCESS, RecordCommand.STOP


# keys --------------------------------------------------------------------------------------------------
def test_key_to_command_mapping_is_lerobot_like():
    assert command_for_key("right") is R and command_for_key("left") is L
    assert command_for_key("s") is S and command_for_key("S") is S and command_for_key("esc") is ESC
    assert command_for_key("w") is None and command_for_key("up") is None
    assert commands_for_keys(["w", "right", "x", "s", "esc"]) == [R, S, ESC]
    custom = {"n": R}
    assert command_for_key("n", custom) is R and command_for_key("right", custom) is None
    with pytest.raises(TypeError, match="key name"):
        command_for_key(3)
    assert set(DEFAULT_RECORD_KEYS.values()) == set(RecordCommand)


@pytest.mark.parametrize("data, keys, tail", [
    (b"\x1b[C", ["right"], b""),
    (b"\x1b[D\x1b[A\x1b[B", ["left", "up", "down"], b""),
    (b"\x1bOC", ["right"], b""),  # application cursor mode
    (b"s", ["s"], b""),
    (b"Sx", ["s", "x"], b""),
    (b"\x1b", [], b"\x1b"),  # maybe the start of a sequence: wait for more
    (b"a\x1b[", ["a"], b"\x1b["),
    (b"\x1bs", ["esc", "s"], b""),  # ESC then another key
    (b"\x1b[1;5C", ["right"], b""),  # ctrl+right: parameters are skipped
    (b"\x1b[15~", [], b""),  # F5: unknown, dropped
    (b"\r \x7f", ["enter", "space", "backspace"], b""),
    ("é".encode(), ["é"], b""),
    ("é".encode()[:1], [], "é".encode()[:1]),  # a cut UTF-8 character waits
    (b"\x03", [], b""),  # control characters other than the named ones are dropped
])
def test_decode_terminal_keys(data, keys, tail):
    assert decode_terminal_keys(data) == (keys, tail)


def test_decode_terminal_keys_final_flushes_a_lone_escape():
    assert decode_terminal_keys(b"\x1b", final=True) == (["esc"], b"")
    assert decode_terminal_keys(b"\x1b[", final=True) == ([], b"")
    with pytest.raises(TypeError):
        decode_terminal_keys("right")


def test_scripted_key_source_by_poll_count_and_by_time():
    src = ScriptedKeySource([(2, "right"), (0, "s"), (2, "esc")])
    src.start()
    assert [src.poll() for _ in range(4)] == [["s"], [], ["right", "esc"], []]
    t = [0.0]
    timed = ScriptedKeySource([(0.5, "left")], clock=lambda: t[0])
    timed.start()
    assert timed.poll() == []
    t[0] = 0.6
    assert timed.poll() == ["left"] and timed.held() == set()


def test_key_source_registry():
    assert set(KEY_SOURCES) == {"auto", "pynput", "terminal", "none"}
    assert isinstance(make_key_source("none"), NullKeySource)
    with pytest.raises(ValueError, match="key source must be one of"):
        make_key_source("joystick")
    # under pytest stdin is not a terminal and pynput is not installed: auto falls back to none
    if not TerminalKeySource.available():
        assert make_key_source("auto").name in ("none", "pynput")


def test_terminal_key_source_on_a_pseudo_terminal():
    pty = pytest.importorskip("pty")
    master, slave = pty.openpty()
    with os.fdopen(slave, "rb", buffering=0) as stream:
        src = TerminalKeySource(stream, hold_s=5.0)
        with src:
            os.write(master, b"s\x1b[C\x1b")
            deadline = __import__("time").monotonic() + 3.0
            got = []
            while __import__("time").monotonic() < deadline and len(got) < 3:
                got += src.poll()
                __import__("time").sleep(0.01)
        assert got == ["s", "right", "esc"]
        assert {"s", "right"} <= src.held()
    os.close(master)


# episode flow --------------------------------------------------------------------------------------------
def test_episode_flow_state_machine():
    c = EpisodeControl(num_episodes=2, reset_time_s=1.0)
    assert c.phase is Phase.RECORDING
    assert c.command(S, steps=3) == [Effect.TOGGLE_SUCCESS] and c.success_mark
    assert c.command(L, steps=5) == [Effect.DISCARD] and not c.success_mark and c.kept == 0
    assert c.command(R, steps=0) == [Effect.DISCARD]  # nothing recorded: nothing kept
    assert c.command(R, steps=7) == [Effect.SAVE] and c.phase is Phase.REVIEW and c.kept == 1
    assert c.command(S, steps=0) == []  # already written
    assert c.review_tick(0.5) == []
    assert c.command(L, steps=0) == [Effect.DELETE_LAST, Effect.START] and c.kept == 0
    assert c.episode_ended(steps=40) == [Effect.SAVED] and c.kept == 1
    assert c.review_tick(1.0) == [Effect.START] and c.phase is Phase.RECORDING
    assert c.episode_ended(steps=12) == [Effect.SAVED] and c.kept == 2
    assert c.command(R, steps=0) == [Effect.STOP] and c.done  # enough kept: the review ends the session
    assert c.command(R, steps=0) == [] and c.interrupt() == []


def test_episode_flow_stop_and_interrupt():
    c = EpisodeControl(3, 0.0)
    assert c.command(ESC, steps=4) == [Effect.SAVE_AND_STOP] and c.done and c.kept == 1
    c = EpisodeControl(3, 0.0)
    assert c.interrupt() == [Effect.STOP_INTERRUPTED] and c.done and c.kept == 0
    c = EpisodeControl(3, 0.0)
    c.episode_ended(5)
    assert c.interrupt() == [Effect.STOP]
    c = EpisodeControl(3, 0.0)
    c.command(R, 2)
    assert c.command(ESC, 0) == [Effect.STOP] and c.kept == 1
    with pytest.raises(RuntimeError):
        c.episode_ended(1)
    with pytest.raises(ValueError, match="num_episodes"):
        EpisodeControl(0, 1.0)
    with pytest.raises(ValueError, match="reset_time_s"):
        EpisodeControl(1, -1.0)
    with pytest.raises(TypeError):
        EpisodeControl(1, 0.0).command("right", 0)


# devices -------------------------------------------------------------------------------------------------
def test_device_specs_and_controllers():
    from teleop import HumanTeleopAgent, KeyboardTeleop, ReplayTracker, SpaceMouseTeleop, UdpGloveReceiver
    from teleop.app.devices import GLOVES, TRACKERS, DeviceContext, KeyJawGlove, build_controller, parse_device_spec

    assert parse_device_spec("replay:/x/y.jsonl", TRACKERS, "tracker").argument == "/x/y.jsonl"
    assert parse_device_spec("udp", GLOVES, "glove").argument is None
    with pytest.raises(ValueError, match=r"tracker must be one of \['keyboard', 'openvr', 'replay', 'udp'\]"):
        parse_device_spec("vive", TRACKERS, "tracker")
    with pytest.raises(ValueError, match="needs an argument"):
        build_controller("replay", "udp")
    with pytest.raises(ValueError, match="takes no argument"):
        build_controller("udp:5", "udp")
    with pytest.raises(ValueError, match="takes no glove"):
        build_controller("keyboard", "udp")
    with pytest.raises(ValueError, match="replaces the tracker"):
        build_controller("udp", None, spacemouse=True)
    with pytest.raises(ValueError, match="ik must be one of"):
        build_controller("udp", "udp", ik="magic")

    held = {"w"}
    ctx = DeviceContext(held_keys=lambda: held, tracker_port=0, glove_port=0)
    kb = build_controller("keyboard", None, ctx=ctx)
    assert isinstance(kb.device, KeyboardTeleop) and "s" not in kb.device.bindings and "x" in kb.device.bindings
    assert isinstance(build_controller(None, None, spacemouse=True, ctx=ctx).device, SpaceMouseTeleop)
    c = build_controller(f"replay:{DATA / (STREAM + '_tracker.jsonl')}", "udp", ctx=ctx)
    assert isinstance(c.device, HumanTeleopAgent) and isinstance(c.parts["tracker"], ReplayTracker)
    assert isinstance(c.parts["glove"], UdpGloveReceiver) and not c.live_latency
    live = build_controller("udp", "udp", ctx=ctx)
    assert live.live_latency and "analytic" in live.description
    nog = build_controller("udp", "none", ctx=ctx)
    assert isinstance(nog.parts["glove"], KeyJawGlove) and nog.device.pinch.source == "sdk"


def test_key_jaw_glove_follows_keys():
    from teleop.app.devices import KeyJawGlove
    from teleop.retarget import PinchRetargeter

    held, t = set(), [0.0]
    g = KeyJawGlove(lambda: held, clock=lambda: t[0], gap_speed_m_s=0.05)
    g.connect()
    pinch = PinchRetargeter(source="sdk", gap_map=g.gap_map)
    assert pinch(g.read()).gap_m == pytest.approx(0.085)
    held.add("e")
    t[0] = 0.5
    assert pinch(g.read()).gap_m == pytest.approx(0.085 - 0.025, abs=1e-9)  # 0.05 m/s for 0.5 s
    t[0] = 5.0
    assert pinch(g.read()).gap_m == pytest.approx(0.0)
    assert g.send_haptics(np.ones(5), np.zeros(5), 0.0) is False


def test_analytic_wrist_ik_matches_iterative():
    from teleop.app.devices import IK_SOLVERS

    a, it = IK_SOLVERS["analytic"](), IK_SOLVERS["iterative"]()
    target = (np.array([0.02, 0.25, -0.01]), np.array([0.0, np.sin(0.3), 0.0, np.cos(0.3)]))
    ra, ri = a.solve(*target, a.home_q), it.solve(*target, it.home_q)
    assert ra.converged and ri.converged
    np.testing.assert_allclose(ra.position, target[0], atol=1e-9)
    np.testing.assert_allclose(ra.position, ri.position, atol=1e-4)
    assert abs(abs(float(np.dot(ra.quat_xyzw, ri.quat_xyzw))) - 1.0) < 1e-6


# live view -----------------------------------------------------------------------------------------------
def test_live_view_png_file_and_http(tmp_path):
    from teleop.app.view import LiveView, png_bytes

    frame = np.zeros((20, 30, 3), np.uint8)
    frame[5:10, 5:20] = (255, 0, 0)
    png = tmp_path / "view.png"
    with LiveView(png, ("127.0.0.1", 0)) as view:
        base = view.url
        assert base.startswith("http://127.0.0.1:")
        with pytest.raises(urllib.error.HTTPError):
            urllib.request.urlopen(base + "frame.png", timeout=5)  # no frame yet
        view.update(frame, {"left_tip_force_N": np.float64(1.5), "phase": "recording", "bad": float("nan")})
        page = urllib.request.urlopen(base, timeout=5).read().decode()
        state = json.loads(urllib.request.urlopen(base + "state.json", timeout=5).read())
        img = urllib.request.urlopen(base + "frame.png?n=0", timeout=5).read()
    assert "live view" in page and "frame.png" in page
    assert state == {"frame": 0, "readouts": {"left_tip_force_N": 1.5, "phase": "recording", "bad": None}}
    assert img == png_bytes(frame) and png.read_bytes() == img
    image = pytest.importorskip("PIL.Image", reason="decode check only; the app itself needs no Pillow")
    np.testing.assert_array_equal(np.asarray(image.open(png)), frame)
    assert not list(tmp_path.glob(".*tmp*"))
    with pytest.raises(ValueError, match="uint8"):
        png_bytes(np.zeros((4, 4), np.float32))


# sessions with the real env and recorder -------------------------------------------------------------------
@pytest.fixture
def recording():
    return pytest.importorskip("defgrasp_env.recording", reason="needs defgrasp_env.recording (HDF5Recorder)")


class KeysThenSigint(ScriptedKeySource):
    """Scripted keys; sends SIGINT to this process at poll ``sigint_at``."""

    def __init__(self, events, sigint_at=None):
        super().__init__(events)
        self.sigint_at = sigint_at

    def poll(self):
        if self.sigint_at is not None and self._polls == self.sigint_at:
            os.kill(os.getpid(), signal.SIGINT)
        return super().poll()


def _keyboard_session(tmp_path, keys, held=("r",), **cfg):
    from teleop.app.devices import DeviceContext, build_controller
    from teleop.app.session import CollectionSession, SessionConfig, make_env_stack

    env, rec, marks = make_env_stack({"object": "cuboid"}, out_dir=tmp_path / "eps")
    ctrl = build_controller("keyboard", None, ctx=DeviceContext(held_keys=lambda: set(held)))
    msgs = []
    cfg = {"num_episodes": 5, "reset_time_s": 0.0, "realtime": False, "seed": 3, **cfg}
    session = CollectionSession(env, ctrl, keys, recorder=rec, marks=marks, config=SessionConfig(**cfg),
                                say=msgs.append, status=lambda line: None)
    return session, msgs


def test_session_keys_save_discard_mark_and_stop(tmp_path, recording):
    # a poll that changes nothing is followed by a step in the same loop pass: polls 0..3 step
    # episode A ("s" at 2), "right" at 4 saves it (4 steps, marked from step 3); B steps at 5, 6;
    # "left" at 7 discards it and C steps at 7, 8, 9; Esc at 10 keeps C (3 steps)
    keys = ScriptedKeySource([(2, "s"), (4, "right"), (7, "left"), (10, "esc")])
    session, msgs = _keyboard_session(tmp_path, keys)
    report = session.run()
    assert report.stopped_by == "esc" and report.discarded == 1 and not report.deleted
    files = sorted((tmp_path / "eps").glob("*.h5"))
    assert [p.name for p in report.saved] == [p.name for p in files] and len(files) == 2
    with h5py.File(files[0]) as f:
        assert f.attrs["num_steps"] == 4 and f.attrs["end_reason"] == "reset"
        np.testing.assert_array_equal(f["info/operator_success"][()], [False, False, True, True])
        y = f["steps/wrist_position"][:, 1]
        assert np.all(np.diff(y) > 0)  # "r" held: the flange rises
    with h5py.File(files[1]) as f:
        assert f.attrs["end_reason"] == "close" and f.attrs["num_steps"] == 3
        assert not f["info/operator_success"][()].any()  # the mark does not carry over
    assert recording.validate_path(tmp_path / "eps").ok
    assert any("discarded the episode" in m for m in msgs)


def test_session_review_rerecord_deletes_the_saved_file(tmp_path, recording):
    # episode A ends on "right" (poll 3); during the review "left" deletes it; B is recorded and kept
    # (the review would last a minute: only the keys move it on; the last "right" ends it)
    keys = ScriptedKeySource([(3, "right"), (4, "left"), (8, "right"), (10, "right")])
    session, msgs = _keyboard_session(tmp_path, keys, num_episodes=1, reset_time_s=60.0)
    report = session.run()
    assert len(report.deleted) == 1 and not report.deleted[0].exists()
    assert len(report.saved) == 1 and report.saved[0].exists() and report.stopped_by == "done"
    assert sorted((tmp_path / "eps").glob("*.h5")) == report.saved


@pytest.mark.parametrize("keep", [False, True])
def test_ctrl_c_keeps_finished_episodes_and_handles_the_current_one(tmp_path, keep, recording):
    keys = KeysThenSigint([(3, "right")], sigint_at=7)  # A saved (3 steps); Ctrl-C during B
    session, msgs = _keyboard_session(tmp_path, keys, keep_interrupted=keep)
    previous = signal.getsignal(signal.SIGINT)
    report = session.run()
    assert signal.getsignal(signal.SIGINT) is previous  # handler restored
    files = sorted((tmp_path / "eps").glob("*.h5"))
    assert report.stopped_by == "interrupt" and len(files) == (2 if keep else 1)
    assert recording.validate_path(tmp_path / "eps").ok
    with h5py.File(files[0]) as f:
        assert f.attrs["num_steps"] == 3
    if keep:
        with h5py.File(files[1]) as f:
            assert f.attrs["end_reason"] == "close" and f.attrs["num_steps"] == 4
    else:
        assert report.discarded == 1 and any("discarded the unfinished episode (4 steps)" in m for m in msgs)
    assert not [p for p in (tmp_path / "eps").iterdir() if p.name.startswith(".")]  # no temp files


def test_session_error_discards_current_and_closes(tmp_path, recording):
    class Boom(ScriptedKeySource):
        def poll(self):
            if self._polls == 5:
                raise RuntimeError("device fell off")
            return super().poll()

    session, msgs = _keyboard_session(tmp_path, Boom([(2, "right")]))
    with pytest.raises(RuntimeError, match="device fell off"):
        session.run()
    assert session.report.stopped_by == "error" and len(list((tmp_path / "eps").glob("*.h5"))) == 1


def test_app_cli_replays_a_recorded_operator_to_success(tmp_path, recording):
    """defgrasp-teleop with replay devices (on the simulation clock): one episode, recorded."""
    from teleop.app.cli import build_parser, run

    meta = json.loads((DATA / f"{STREAM}.json").read_text())
    args = build_parser().parse_args([
        "--tracker", f"replay:{DATA / (STREAM + '_tracker.jsonl')}", "--glove", f"replay:{DATA / (STREAM + '_glove.jsonl')}",
        "--object", meta["env_kwargs"]["object"], "--youngs-modulus", str(meta["env_kwargs"]["youngs_modulus"]),
        "--seed", str(meta["seed"]), "--fixed-seed", "--episodes", "1", "--reset-time-s", "0", "--keys", "none",
        "--out", str(tmp_path / "eps"), "--view-port", "0", "--view-png", str(tmp_path / "view.png"),
        "--no-realtime", "--ik", "iterative",
    ])
    msgs = []
    report = run(args, say=msgs.append)
    assert len(report.saved) == 1, msgs
    with h5py.File(report.saved[0]) as f:
        assert f.attrs["is_success"], "the replayed operator should lift the cuboid to the goal"
        assert f.attrs["end_reason"] == "terminated" and f.attrs["policy"] == "teleop"
    assert (tmp_path / "view.png").stat().st_size > 1000
