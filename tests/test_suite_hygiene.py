"""Rules the test suite holds itself to (issue 27 item 6), read from the tests' syntax trees:
every subprocess a test starts has a timeout, and no test signals its own process (pytest) or
reads the host's network tables. Code a test hands to a child process is a string constant, not
a call, so the child may signal itself."""

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
_SUBPROCESS_CALLS = {"run", "Popen", "call", "check_call", "check_output"}


def _calls(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and isinstance(node.func.value, ast.Name):
            yield node, node.func.value.id, node.func.attr


def _where(path, node):
    return f"{path.name}:{node.lineno}"


@pytest.mark.parametrize("path", sorted(TESTS.glob("*.py")), ids=lambda p: p.name)
def test_every_subprocess_has_a_timeout_and_no_test_signals_pytest(path):
    untimed, signalling = [], []
    for node, module, name in _calls(path):
        keywords = {k.arg for k in node.keywords}
        if module == "subprocess" and name in _SUBPROCESS_CALLS and "timeout" not in keywords:
            if name != "Popen" or not _waited_with_timeout(path):
                untimed.append(_where(path, node))
        if (module, name) in {("os", "kill"), ("os", "killpg"), ("signal", "raise_signal"), ("signal", "pthread_kill")}:
            signalling.append(_where(path, node))
    assert untimed == [], "a subprocess without timeout="
    assert signalling == [], "a real signal sent from the test process (use the fake_signals fixture)"
    assert "/proc/net" not in path.read_text(encoding="utf-8") or path.name == Path(__file__).name


def _waited_with_timeout(path):
    """A Popen is bounded when the file waits for it with a timeout (communicate/wait)."""
    return any(name in {"communicate", "wait"} and any(k.arg == "timeout" for k in node.keywords)
               for node, _, name in _calls(path))


def test_the_rule_sees_an_untimed_subprocess_and_a_signal(tmp_path):
    bad = tmp_path / "test_bad.py"
    bad.write_text("import os, signal, subprocess\n"
                   "def test_x():\n"
                   "    subprocess.run(['true'])\n"
                   "    os.kill(os.getpid(), signal.SIGTERM)\n")
    with pytest.raises(AssertionError, match="timeout"):
        test_every_subprocess_has_a_timeout_and_no_test_signals_pytest(bad)
    bad.write_text(bad.read_text().replace("['true'])", "['true'], timeout=5)"))
    with pytest.raises(AssertionError, match="real signal"):
        test_every_subprocess_has_a_timeout_and_no_test_signals_pytest(bad)
