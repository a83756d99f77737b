"""docs/api.md is generated from the docstrings and always current; every public name has a
numpydoc docstring that documents each of its arguments."""

import doctest
import importlib.util
import inspect

import pytest

import tcr_accuracy

from conftest import REPO

_spec = importlib.util.spec_from_file_location("make_api_docs", REPO / "scripts" / "make_api_docs.py")
make_api_docs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_api_docs)

#: every public name carries an Examples section that runs (issue 38 item 6)
WITH_EXAMPLES = tuple(tcr_accuracy._EXPORTS)


def test_api_page_is_current():
    """Regenerate the page: it must equal docs/api.md byte for byte (else run the script)."""
    page = (REPO / "docs" / "api.md").read_text()
    assert page == make_api_docs.render_api(), "docs/api.md is stale: run python scripts/make_api_docs.py"
    for name in tcr_accuracy._EXPORTS:
        assert f"\n### {name}\n" in page


def test_the_section_parser_reads_numpydoc():
    doc = inspect.cleandoc("""Summary line.

        Parameters
        ----------
        a, b : float
            Two numbers.
        **options
            Passed on.

        Returns
        -------
        float
        """)
    summary, sections = make_api_docs.split_sections(doc)
    assert summary == "Summary line."
    assert list(sections) == ["Parameters", "Returns"]
    assert make_api_docs.documented_names(sections["Parameters"]) == ["a", "b", "options"]


def _arguments(obj) -> list[str]:
    return [p.name for p in inspect.signature(obj).parameters.values() if p.name != "self"]


@pytest.mark.parametrize("name", list(tcr_accuracy._EXPORTS))
def test_public_name_has_a_numpydoc_docstring_for_every_argument(name):
    obj = getattr(tcr_accuracy, name)
    doc = inspect.getdoc(obj)
    assert doc, f"{name} has no docstring"
    summary, sections = make_api_docs.split_sections(doc)
    assert summary, f"{name}: no summary line"
    documented = make_api_docs.documented_names(sections.get("Parameters", ""))
    if inspect.isclass(obj):  # a dataclass' fields may be documented as its Attributes
        documented += make_api_docs.documented_names(sections.get("Attributes", ""))
    missing = [a for a in _arguments(obj) if a not in documented]
    assert not missing, f"{name}: Parameters does not document {missing}"
    if not inspect.isclass(obj):
        assert "Returns" in sections, f"{name}: no Returns section"
    examples = make_api_docs.split_sections(make_api_docs.docstring(name, obj))[1].get("Examples", "")
    assert ">>> " in examples, f"{name}: no Examples section"
    assert "+SKIP" not in examples, f"{name}: an example that does not run"


@pytest.mark.parametrize("name", WITH_EXAMPLES)
def test_the_examples_run_and_print_what_they_say(name, monkeypatch):
    """doctest of each Examples section as docs/api.md shows it, from the repository root."""
    monkeypatch.chdir(REPO)
    obj = getattr(tcr_accuracy, name)
    examples = make_api_docs.split_sections(make_api_docs.docstring(name, obj))[1]["Examples"]
    test = doctest.DocTestParser().get_doctest(examples, {}, name, name, 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert runner.failures == 0 and runner.tries > 0
