"""UDP glove/tracker streams over real loopback sockets: the receiver fed by the real senders."""

import logging
import struct
import time
import zlib

import numpy as np
import pytest

from teleop.sensors import UdpGloveReceiver, UdpGloveSender, UdpTrackerReceiver, UdpTrackerSender
from teleop.sensors import wire
from teleop.se3 import pose_to_matrix, rotvec_to_quat

RNG = np.random.default_rng(0)


def angles(v=0.1):
    return np.full((5, 4), v)


def tips(v=0.05):
    return np.full((5, 3), v)


def settle(receiver, predicate=None, timeout=1.0):
    """Read until the predicate holds on a sample (datagrams need a moment on loopback)."""
    deadline = time.monotonic() + timeout
    while True:
        s = receiver.read()
        if (predicate(s) if predicate else True) or time.monotonic() > deadline:
            return s
        time.sleep(0.002)


@pytest.fixture
def glove_pair():
    rx = UdpGloveReceiver(port=0, timeout_s=0.2, max_delay_s=0.05)
    rx.connect()
    tx = UdpGloveSender(rx.address, bind_host="127.0.0.1")
    yield rx, tx
    tx.close()
    rx.disconnect()


def test_roundtrip_exact_float32(glove_pair):
    rx, tx = glove_pair
    a = RNG.uniform(-1.5, 1.5, (5, 4))
    p = RNG.uniform(-0.2, 0.2, (5, 3))
    tx.send(a, p)
    s = settle(rx, lambda s: s.connected)
    assert s.connected
    np.testing.assert_array_equal(s.joint_angles, a.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(s.fingertip_positions, p.astype(np.float32).astype(np.float64))
    assert rx.right_hand is True
    assert abs(s.timestamp_s - time.monotonic()) < 1.0
    assert rx.stats.accepted == 1 and rx.stats.dropped == 0


def test_no_data_reads_disconnected(glove_pair):
    rx, _ = glove_pair
    s = rx.read()
    assert not s.connected and np.all(s.joint_angles == 0)


def test_latest_sample_wins(glove_pair):
    rx, tx = glove_pair
    for v in (0.1, 0.2, 0.3):
        tx.send(angles(v), tips())
    time.sleep(0.05)
    s = rx.read()
    assert s.joint_angles[0, 0] == pytest.approx(0.3)
    assert rx.stats.accepted == 1 and rx.stats.superseded == 2 and rx.stats.dropped == 0


def test_glove_flag_disconnected(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(), tips(), connected=False)
    time.sleep(0.05)
    assert not rx.read().connected
    assert rx.stats.accepted == 1


def _valid_bytes(seq=1, t=None, values=None, version=1, magic=b"DGTP", msg_type=1):
    vals = np.zeros(35) if values is None else values
    body = struct.pack("<4sBBHIId", magic, version, msg_type, 1, 7, seq, time.monotonic() if t is None else t)
    body += struct.pack("<35f", *vals)
    return body + struct.pack("<I", zlib.crc32(body))


@pytest.mark.parametrize(
    "data, reason",
    [
        (b"hello", "too short"),
        (_valid_bytes()[:-1], "must be 168 bytes"),
        (_valid_bytes() + b"\0", "must be 168 bytes"),
        (_valid_bytes(magic=b"XXXX"), "bad magic"),
        (_valid_bytes(version=2), "unsupported protocol version 2"),
        (_valid_bytes()[:-4] + b"\0\0\0\0", "CRC"),
        (_valid_bytes(values=np.r_[np.full(20, np.nan), np.zeros(15)]), "non-finite"),
        (_valid_bytes(values=np.r_[np.zeros(20), np.full(15, 50.0)]), "mm sent instead of m"),
        (_valid_bytes(values=np.r_[np.full(20, 7.0), np.zeros(15)]), "joint angle"),
    ],
)
def test_malformed_dropped_and_counted(glove_pair, caplog, data, reason):
    rx, tx = glove_pair
    with caplog.at_level(logging.WARNING, logger="teleop.udp"):
        tx.send_raw(data)
        time.sleep(0.05)
        s = rx.read()
    assert not s.connected
    assert rx.stats.malformed == 1 and rx.stats.accepted == 0
    assert reason in caplog.text and "1 malformed drops so far" in caplog.text
    # a good datagram afterwards still gets through
    tx.send(angles(), tips())
    assert settle(rx, lambda s: s.connected).connected


def test_wrong_message_type_on_glove_port(glove_pair):
    rx, tx = glove_pair
    tx.send_raw(wire.encode(wire.MSG_TRACKER_POSE, 3, 1, 1, time.monotonic(), [0, 0, 0, 0, 0, 0, 1]))
    time.sleep(0.05)
    rx.read()
    assert rx.stats.malformed == 1


def test_out_of_order_and_duplicate_dropped(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(0.5), tips(), sequence=10)
    tx.send(angles(0.1), tips(), sequence=9)  # older
    tx.send(angles(0.2), tips(), sequence=10)  # duplicate
    time.sleep(0.05)
    s = rx.read()
    assert s.joint_angles[0, 0] == pytest.approx(0.5)
    assert rx.stats.out_of_order == 2 and rx.stats.accepted == 1
    tx.send(angles(0.7), tips(), sequence=11)
    assert settle(rx, lambda s: s.joint_angles[0, 0] == pytest.approx(0.7)).joint_angles[0, 0] == pytest.approx(0.7)


def test_sequence_wraparound_accepted(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(0.1), tips(), sequence=0xFFFFFFFF)
    tx.send(angles(0.2), tips(), sequence=0)
    time.sleep(0.05)
    assert rx.read().joint_angles[0, 0] == pytest.approx(0.2)
    assert rx.stats.accepted + rx.stats.superseded == 2 and rx.stats.out_of_order == 0
    assert wire.seq_newer(0, 0xFFFFFFFF) and not wire.seq_newer(0xFFFFFFFF, 0)


def test_stale_dropped(glove_pair):
    rx, tx = glove_pair
    t0 = time.monotonic()
    tx.send(angles(0.1), tips(), timestamp_s=t0)
    time.sleep(0.01)
    rx.read()
    tx.send(angles(0.2), tips(), timestamp_s=t0 + 0.01)
    time.sleep(0.01)
    rx.read()
    # newer sequence, but captured 0.5 s earlier than its predecessors: it sat in a queue somewhere
    tx.send(angles(0.9), tips(), timestamp_s=t0 - 0.5)
    time.sleep(0.02)
    s = rx.read()
    assert rx.stats.stale == 1
    assert s.joint_angles[0, 0] == pytest.approx(0.2)


def test_sender_clock_offset_is_not_stale(glove_pair):
    """Sender and receiver clocks differ by hours: only delay *variation* matters."""
    rx, tx = glove_pair
    base = 12345.0  # an unrelated sender epoch
    for i in range(5):
        tx.send(angles(0.1 * i), tips(), timestamp_s=base + 0.01 * i)
        time.sleep(0.01)
    time.sleep(0.02)
    s = rx.read()
    assert rx.stats.stale == 0 and rx.stats.accepted + rx.stats.superseded == 5 and s.connected


def test_slow_reader_is_not_stale(glove_pair):
    """Datagrams that queue up while the reader is busy are superseded, not stale."""
    rx, tx = glove_pair
    for i in range(10):
        tx.send(angles(0.01 * i), tips())
        time.sleep(0.015)  # the last datagram is 0.135 s younger than the first > max_delay_s
    s = rx.read()
    assert s.connected and s.joint_angles[0, 0] == pytest.approx(0.09)
    assert rx.stats.stale == 0 and rx.stats.superseded == 9


def test_timeout_disconnects_then_reconnects(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(0.3), tips())
    assert settle(rx, lambda s: s.connected).connected
    time.sleep(0.3)  # > timeout_s = 0.2
    s = rx.read()
    assert not s.connected
    assert s.joint_angles[0, 0] == pytest.approx(0.3)  # last values carried
    tx.send(angles(0.4), tips())
    s = settle(rx, lambda s: s.connected)
    assert s.connected and s.joint_angles[0, 0] == pytest.approx(0.4)


def test_other_stream_dropped_while_live_adopted_after_silence(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(0.1), tips())
    settle(rx, lambda s: s.connected)
    with UdpGloveSender(rx.address, bind_host="127.0.0.1") as restarted:
        restarted.send(angles(0.6), tips())
        time.sleep(0.05)
        assert rx.read().joint_angles[0, 0] == pytest.approx(0.1)
        assert rx.stats.other_stream == 1
        time.sleep(0.25)  # first stream silent > timeout
        restarted.send(angles(0.6), tips())
        s = settle(rx, lambda s: s.connected)
        assert s.joint_angles[0, 0] == pytest.approx(0.6)
        assert rx.stats.stream_id == restarted.stream_id


def test_haptics_roundtrip(glove_pair):
    rx, tx = glove_pair
    assert rx.send_haptics(np.zeros(5), np.zeros(5), 0.0) is False  # no peer known yet
    tx.send(angles(), tips())
    settle(rx, lambda s: s.connected)
    ff = np.array([0.25, 0.5, 0.0, 0.0, 1.0])
    vib = np.array([0.0, 0.6, 0.0, 0.0, 0.0])
    assert rx.send_haptics(ff, vib, 0.08) is True
    cmd = None
    deadline = time.monotonic() + 1.0
    while cmd is None and time.monotonic() < deadline:
        cmd = tx.poll_haptics()
        time.sleep(0.002)
    np.testing.assert_allclose(cmd.force_feedback, ff, atol=1e-7)
    np.testing.assert_allclose(cmd.vibration, vib, atol=1e-7)
    assert cmd.vibration_duration_s == pytest.approx(0.08)
    assert cmd.sequence == 1


def test_sender_drops_malformed_haptics(glove_pair):
    rx, tx = glove_pair
    tx.send(angles(), tips())
    settle(rx, lambda s: s.connected)
    rx._rx.sendto(b"garbage", tx.address)
    time.sleep(0.05)
    assert tx.poll_haptics() is None and tx.haptics_dropped == 1


def test_read_before_connect_raises():
    rx = UdpGloveReceiver(port=0)
    with pytest.raises(RuntimeError, match="connect"):
        rx.read()


def test_tracker_stream():
    rx = UdpTrackerReceiver(port=0, timeout_s=0.2)
    with rx, UdpTrackerSender(rx.address, bind_host="127.0.0.1") as tx:
        T = pose_to_matrix([0.1, 1.2, -0.3], rotvec_to_quat([0.3, -0.2, 0.5]))
        tx.send(T)
        s = settle(rx, lambda s: s.valid)
        assert s.valid
        np.testing.assert_allclose(s.pose, T, atol=1e-6)
        # lost tracking: invalid, pose kept at the last valid one
        tx.send(np.eye(4), valid=False)
        s = settle(rx, lambda s: not s.valid)
        assert not s.valid
        np.testing.assert_allclose(s.pose, T, atol=1e-6)
        tx.send(T, connected=False)
        assert not settle(rx, lambda s: not s.valid).valid
        tx.send(T)
        assert settle(rx, lambda s: s.valid).valid
        time.sleep(0.3)
        assert not rx.read().valid  # timeout


def test_tracker_rejects_non_unit_quaternion():
    rx = UdpTrackerReceiver(port=0)
    with rx, UdpTrackerSender(rx.address, bind_host="127.0.0.1") as tx:
        tx.send_raw(wire.encode(wire.MSG_TRACKER_POSE, 3, tx.stream_id, 1, time.monotonic(), [0, 0, 0, 0, 0, 0, 2.0]))
        time.sleep(0.05)
        assert not rx.read().valid
        assert rx.stats.malformed == 1


def test_datagram_sizes_match_the_protocol_doc():
    assert wire.SIZES == {1: 168, 2: 72, 3: 56}
    assert wire.HEADER.size == 24
