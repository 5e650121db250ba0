"""The bad-input corpus (tests/bad_inputs/manifest.toml): each mistake gives one clear message,
a non-zero exit, no traceback, and writes nothing."""

import tomllib

import pytest

from conftest import REPO, run_cli

CORPUS = REPO / "tests" / "bad_inputs"
ENTRIES = tomllib.loads((CORPUS / "manifest.toml").read_text())["input"]


def test_corpus_is_large_enough():
    assert len(ENTRIES) >= 40
    for entry in ENTRIES:
        assert (CORPUS / entry["file"]).is_file(), entry["file"]


@pytest.mark.parametrize("entry", ENTRIES, ids=[f"{e['file']}:{e['command'][0]}" for e in ENTRIES])
def test_bad_input(entry, tmp_path, bone_library):
    out = tmp_path / "out"
    out.mkdir()
    args = [a.replace("{file}", str(CORPUS / entry["file"])).replace("{out}", str(out)) for a in entry["command"]]
    proc = run_cli(*args, cwd=tmp_path, env={"FEMSTUDY_CACHE": str(tmp_path / "cache")})
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert entry["expect"] in proc.stderr, proc.stderr
    messages = [line for line in proc.stderr.splitlines() if line and not line.startswith("[")]  # not progress
    assert len(messages) == 1 and messages[0].startswith("femstudy: error: "), proc.stderr
    assert list(out.iterdir()) == [], "something was written to the output location"
    assert list(bone_library.iterdir()) == [], "a bone set was saved"
