"""The code in README.md and docs/*.md cannot drift from the package.

Every fenced block says what it is:

- ``python``: a script; it is executed, in a fresh folder holding a copy of ``cases/`` and the
  session's shared cache as ``.femstudy-cache`` (so it runs as a user in a checkout would, on the
  meshes and answers the other tests already made);
- ``toml``: case-file sections; they must validate as a case;
- ``console``: a transcript: lines starting with ``$ `` are commands, the rest their output;
  each ``femstudy`` command must parse (its options and choices exist) and the case, sweep and
  recording files it names must exist or be written by an earlier command of the block;
- ``bash``: commands to run; the README's test command is exactly what CI runs (.ci/run), and
  its main-study command is run by :func:`test_readme_main_study_runs`;
- ``json`` and ``text``: output, not run.

A block without a language fails: it must be marked as code or as output.
"""

import os
import re
import shlex
import shutil
import subprocess
import sys

import pytest

from conftest import AFTER_MAIN_STUDY, MAIN_STUDY, REPO

DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
LANGUAGES = {"python", "toml", "console", "bash", "json", "text"}
FENCE = re.compile(r"^```(\S*)\n(.*?)^```\s*$", re.M | re.S)


def blocks(language: str | None = None) -> list:
    found = []
    for path in DOCUMENTS:
        text = path.read_text(encoding="utf-8")
        for match in FENCE.finditer(text):
            line = text.count("\n", 0, match.start()) + 1
            if language is None or match.group(1) == language:
                # a script is run whole: heavy, run early, but after the main study (the README's
                # script runs the default case again and reads the main study's answers)
                marks = pytest.mark.slow(rank=AFTER_MAIN_STUDY) if language == "python" else ()
                found.append(pytest.param(match.group(1), match.group(2), id=f"{path.name}:{line}", marks=marks))
    return found


@pytest.mark.parametrize("language, code", blocks())
def test_every_block_says_what_it_is(language, code):
    assert language in LANGUAGES, f"a fenced block must be marked as one of {sorted(LANGUAGES)}, got {language!r}"


@pytest.fixture
def checkout(tmp_path, shared_cache, monkeypatch):
    """A folder like a user's checkout: cases/ and the mesh cache, nothing else."""
    shutil.copytree(REPO / "cases", tmp_path / "cases")
    (tmp_path / ".femstudy-cache").symlink_to(shared_cache, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("FEMSTUDY_BONES", str(tmp_path / "bones"))
    return tmp_path


@pytest.mark.parametrize("language, code", blocks("python"))
def test_python_blocks_run(language, code, checkout):
    exec(compile(code, "<documentation block>", "exec"), {"__name__": "__doc_block__"})


@pytest.mark.parametrize("language, code", blocks("toml"))
def test_toml_blocks_are_valid_case_sections(language, code):
    from femstudy.casefile import parse_case

    text = code if re.search(r"^name\s*=", code, re.M) else 'name = "documented"\n' + code
    parse_case(text)


def _commands(code: str) -> list[list[str]]:
    return [shlex.split(line[2:], comments=True) for line in code.splitlines() if line.startswith("$ ")]


@pytest.mark.parametrize("language, code", blocks("console"))
def test_console_commands_parse_and_name_existing_files(language, code):
    from femstudy.cli import build_parser

    parser = build_parser()
    written: set[str] = set()
    scripted = False  # files a script wrote are not known here
    for words in _commands(code):
        words = [w for w in words if not re.fullmatch(r"[A-Z_]+=\S*", w)]  # environment settings
        if words[:1] == ["python"]:
            if words[1] == "-c":
                compile(words[2], "<documented command>", "exec")
            else:
                assert (REPO / words[1]).is_file(), f"{' '.join(words)}: {words[1]} does not exist"
            scripted = True
            continue
        if words[:1] != ["femstudy"]:
            continue
        args = parser.parse_args(words[1:])
        for name in ("cases", "case", "file", "recording", "runs"):
            value = getattr(args, name, None)
            for item in value if isinstance(value, list) else [value]:
                if item is not None and not scripted and str(item) not in written:
                    assert (REPO / str(item)).exists() or any(str(item).startswith(w) for w in written), \
                        f"{' '.join(words)}: {item} does not exist"
        for name in ("out", "dataset", "csv", "json"):
            if getattr(args, name, None) is not None:
                written.add(str(getattr(args, name)))


def _readme_bash() -> list[str]:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    return [m.group(2).strip() for m in FENCE.finditer(text) if m.group(1) == "bash"]


def test_ci_runs_the_readme_test_command():
    ci = [line for line in (REPO / ".ci" / "run").read_text().splitlines() if line and not line.startswith(("#", "set ", "cd "))]
    assert ci == [next(c for c in _readme_bash() if "pytest" in c)]


@pytest.mark.slow(rank=MAIN_STUDY)
def test_readme_main_study_runs(tmp_path, shared_cache):
    """The README's first command, after its install step: the main study on the built-in femur
    at the case's own settings, as a new user runs it. It is the session's first test, and no
    other test meshes this case at 8 mm in the shared cache, so it meshes and computes everything
    itself; the scripts that run the case again later (conftest.AFTER_MAIN_STUDY) read its kept
    answers."""
    command = next(c for c in _readme_bash() if "femstudy run" in c).split("&&")[-1].strip()
    words = shlex.split(command)
    assert words[0].endswith("femstudy") and words[1:] == ["run", "cases/middiaphysis.toml"]
    env = {**os.environ, "FEMSTUDY_CACHE": str(shared_cache)}
    proc = subprocess.run([sys.executable, "-m", "femstudy", *words[1:], "--out", str(tmp_path / "out"), "--quiet"],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stderr
    assert "max deflection" in proc.stdout and (tmp_path / "out" / "summary.json").is_file()
