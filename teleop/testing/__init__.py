"""Test-data tools (not used by the app): ``synth`` makes synthetic operator streams (the
retargeting inverted, ``python -m teleop.testing.synth``) and ``udp_replay`` plays recorded streams
into the UDP receivers (``python -m teleop.testing.udp_replay``). Used by tests, the teleop
benchmark and for trying the app without hardware."""
