"""Safe files, checked on the source: every output goes through ``quadfault.fileio`` (atomic,
no silent overwrite), and nothing unpickles a user-provided path except the stable-baselines3
model and VecNormalize loaders (which the docs warn about)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("quadfault", "estimators", "agents", "quad_fault_env", "examples", "benchmarks")

#: direct file writes that bypass quadfault.fileio
WRITE_PATTERNS = {
    "open for writing": re.compile(r"""\bopen\([^)]*["'](?:w|a|x|wb|ab|xb|w\+|r\+)["']"""),
    "savefig": re.compile(r"(?<!buf)\.savefig\((?!buf)"),
    "to_csv": re.compile(r"\.to_csv\("),
    "json.dump to a file": re.compile(r"\bjson\.dump\("),
    "numpy save": re.compile(r"\bnp\.save(?:z|z_compressed|txt)?\("),
    "write_text/write_bytes": re.compile(r"\.write_(?:text|bytes)\("),
    "pickle.dump": re.compile(r"\bpickle\.dump\("),
    "SB3 save": re.compile(r"\b(?:model|vn)\.save\("),
}
#: (file, pattern) -> why it is allowed
WRITE_ALLOWED = {
    ("quadfault/fileio.py", "savefig"): "atomic_savefig renders into a buffer",
    ("agents/train_eval.py", "numpy save"): "np.savez into an in-memory buffer that "
    "atomic_write_bytes then writes",
    ("benchmarks/bench_diagnosis.py", "write_text/write_bytes"): "the reference revision's "
    "modules, into its own "
    "temporary folder",
    ("agents/train_eval.py", "SB3 save"): "model.save into an in-memory buffer that "
    "atomic_write_files then writes",
    ("quadfault/io/importers/dataflash.py", "open for writing"): "os.devnull, to silence "
    "pymavlink's own stderr while it reads",
}

#: loaders that can execute code from a file
LOAD_PATTERNS = {
    "pickle.load": re.compile(r"\bpickle\.loads?\("),
    "allow_pickle=True": re.compile(r"allow_pickle\s*=\s*True"),
    "torch.load": re.compile(r"\btorch\.load\("),
    "SB3 load": re.compile(r"\b(?:VecNormalize|cls|PPO|SAC|model_cls|algo_cls)\.load\("),
    "joblib/dill": re.compile(r"\b(?:joblib|dill|cloudpickle)\.load"),
}
LOAD_ALLOWED = {("agents/train.py", "SB3 load")}


def _sources():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


def _hits(patterns):
    found = {}
    for rel, text in _sources():
        for name, rx in patterns.items():
            lines = [
                i + 1
                for i, line in enumerate(text.splitlines())
                if rx.search(line) and not line.lstrip().startswith("#")
            ]
            if lines:
                found[(rel, name)] = lines
    return found


def test_scan_finds_what_it_looks_for():
    assert WRITE_PATTERNS["open for writing"].search('with open(p, "w") as fh:')
    assert WRITE_PATTERNS["savefig"].search("fig.savefig(path)")
    assert not WRITE_PATTERNS["savefig"].search("fig.savefig(buf, format=fmt)")
    assert LOAD_PATTERNS["SB3 load"].search("VecNormalize.load(str(p), venv)")
    assert LOAD_PATTERNS["allow_pickle=True"].search("np.load(p, allow_pickle=True)")


def test_every_writer_goes_through_fileio():
    unexpected = {k: v for k, v in _hits(WRITE_PATTERNS).items() if k not in WRITE_ALLOWED}
    assert not unexpected, f"direct file writes (use quadfault.fileio): {unexpected}"


def test_only_sb3_loaders_unpickle_user_files():
    unexpected = {k: v for k, v in _hits(LOAD_PATTERNS).items() if k not in LOAD_ALLOWED}
    assert not unexpected, f"pickle-capable loaders outside agents/train.py: {unexpected}"


def test_docs_warn_about_pickled_agent_files():
    text = (ROOT / "docs" / "reliability.md").read_text(encoding="utf-8").lower()
    assert "pickle" in text and "vecnormalize" in text and "trust" in text


@pytest.mark.parametrize(
    "name", ["atomic_write_bytes", "atomic_write_text", "atomic_savefig", "atomic_write_files"]
)
def test_fileio_writers_refuse_to_overwrite(tmp_path, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from quadfault import fileio
    from quadfault.errors import QuadfaultError

    target = tmp_path / "out.png"
    target.write_text("keep")
    fig = plt.figure()
    calls = {
        "atomic_write_bytes": lambda f: fileio.atomic_write_bytes(target, b"x", force=f),
        "atomic_write_text": lambda f: fileio.atomic_write_text(target, "x", force=f),
        "atomic_savefig": lambda f: fileio.atomic_savefig(fig, target, force=f),
        "atomic_write_files": lambda f: fileio.atomic_write_files({target: "x"}, force=f),
    }
    with pytest.raises(QuadfaultError, match="--force"):
        calls[name](False)
    assert target.read_text() == "keep"
    calls[name](True)
    assert target.read_bytes() != b"keep"
    plt.close(fig)
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_written_files_respect_the_umask(tmp_path, umask):
    """Atomic writes create their files as ``open()`` would: mode 0666 less the umask (a
    colleague in the group can read ``results/`` when the umask lets them)."""
    import os
    import stat

    from quadfault import fileio

    before = os.umask(umask)
    try:
        fileio.atomic_write_files({tmp_path / "a.csv": "t\n0\n", tmp_path / "a.json": "{}"})
        fileio.atomic_write_text(tmp_path / "b.md", "x")
        fileio.atomic_write_text(tmp_path / "b.md", "y", force=True)
    finally:
        os.umask(before)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()}
    assert modes == dict.fromkeys(["a.csv", "a.json", "b.md"], 0o666 & ~umask)


class _FakeModel:
    """Stands in for an SB3 model: ``save`` writes into the file object it is given."""

    def __init__(self, payload: bytes, vecnorm=None):
        self.payload, self.vecnorm = payload, vecnorm

    def save(self, fh):
        fh.write(self.payload)

    def get_vec_normalize_env(self):
        return self.vecnorm


def test_save_agent_is_atomic_and_refuses_to_overwrite(tmp_path, monkeypatch):
    import os
    import pickle

    from agents.train import MODEL_FILE, VECNORM_FILE, save_agent
    from quadfault.errors import QuadfaultError

    save_agent(_FakeModel(b"old", {"mean": 0}), tmp_path)
    assert (tmp_path / MODEL_FILE).read_bytes() == b"old"
    assert pickle.loads((tmp_path / VECNORM_FILE).read_bytes()) == {"mean": 0}
    with pytest.raises(QuadfaultError, match="--force"):
        save_agent(_FakeModel(b"new"), tmp_path)

    def interrupted(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        save_agent(_FakeModel(b"new", {"mean": 1}), tmp_path, force=True)
    monkeypatch.undo()
    assert (tmp_path / MODEL_FILE).read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([MODEL_FILE, VECNORM_FILE])
