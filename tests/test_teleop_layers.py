"""The teleop package's layers, read from the import statements (no import needed): sensors read
hardware and streams and import nothing that makes actions; TeleopDevices import sensors, never the
app; the app and the library never import the test-data tools."""

from __future__ import annotations

import ast
import pathlib

import pytest

TELEOP = pathlib.Path(__file__).resolve().parents[1] / "teleop"


def _imports(path: pathlib.Path) -> set[str]:
    """Absolute names of the teleop modules that ``path`` imports (relative imports resolved)."""
    package = ".".join(path.relative_to(TELEOP.parent).with_suffix("").parts)
    if path.name != "__init__.py":
        package = package.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module
            out.add(name)
            out |= {f"{name}.{a.name}" for a in node.names}
    return {n for n in out if n == "teleop" or n.startswith("teleop.")}


def _modules(sub: str) -> list[pathlib.Path]:
    return sorted((TELEOP / sub).rglob("*.py")) if sub else sorted(TELEOP.glob("*.py"))


ACTION_MAKERS = ("teleop.devices", "teleop.teleop_device", "teleop.agent", "teleop.app", "teleop.retarget",
                 "teleop.haptics", "teleop.testing")


@pytest.mark.parametrize("path", _modules("sensors"), ids=lambda p: p.name)
def test_sensors_import_no_action_maker(path):
    bad = sorted(n for n in _imports(path) if n.startswith(ACTION_MAKERS))
    assert not bad, f"{path.name} imports {bad}"


@pytest.mark.parametrize("path", _modules("devices"), ids=lambda p: p.name)
def test_teleop_devices_do_not_import_the_app_or_test_tools(path):
    bad = sorted(n for n in _imports(path) if n.startswith(("teleop.app", "teleop.testing", "teleop.agent")))
    assert not bad, f"{path.name} imports {bad}"


@pytest.mark.parametrize("path", [p for p in sorted(TELEOP.rglob("*.py")) if "testing" not in p.parts],
                         ids=lambda p: str(p.relative_to(TELEOP)))
def test_only_tests_and_benchmarks_use_the_test_data_tools(path):
    assert not any(n.startswith("teleop.testing") for n in _imports(path))


def test_the_resolver_sees_relative_imports():
    """Guard against a resolver that sees nothing (which would make the tests above pass vacuously)."""
    names = _imports(TELEOP / "devices" / "spacemouse.py")
    assert {"teleop.sensors.spacemouse", "teleop._validate", "teleop.devices.velocity"} <= names
    assert "teleop.sensors.base" in _imports(TELEOP / "testing" / "synth.py")
    assert "teleop.teleop_device" in _imports(TELEOP / "devices" / "velocity.py")
