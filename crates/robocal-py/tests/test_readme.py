"""README.md's "From Python" session runs as written and prints what it shows (doctest)."""

import doctest
import pathlib
import re

REPO = pathlib.Path(__file__).resolve().parents[3]


def readme_session():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## From Python\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```pycon\n(.*?)```", section, flags=re.S)
    assert blocks, "README's 'From Python' section has no pycon block"
    return "\n".join(blocks)


def test_the_readme_python_session_prints_what_it_shows():
    parser = doctest.DocTestParser()
    test = parser.get_doctest(readme_session(), {}, "README.md: From Python", str(REPO / "README.md"), 0)
    assert len(test.examples) >= 10, "the session lost its examples"
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} README examples differ (printed above)"
