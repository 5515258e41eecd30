"""Every file a command writes is written whole or not at all, and an output
path that cannot be written is one line and EXIT_OUTPUT.

The paths are real ones the kernel refuses (tests may run as root, where a
read-only mode stops nothing): a directory under a regular file, a file in
/proc; a full disk is a file-size limit (RLIMIT_FSIZE: the kernel fails the
write past it with EFBIG, as a full disk fails it with ENOSPC).
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import time
from pathlib import Path

import pytest
from conftest import BIN, next_domain, release_domain

from winder.cli.exits import EXIT_OUTPUT
from winder.contract.files import OutputError, atomic_file, new_directory, write_text
from winder.record.bag import bags_in

TINY = ("--turns-per-layer", "4", "--layers", "1", "--poles", "1")


def winder(*args: str, cwd: Path | None = None, fsize: int | None = None) -> subprocess.CompletedProcess[str]:
    def limit() -> None:
        if fsize is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    return subprocess.run(
        [str(BIN / "winder"), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        preexec_fn=limit,
    )


def assert_output_error(r: subprocess.CompletedProcess[str], path: str, reason: str) -> None:
    assert r.returncode == EXIT_OUTPUT, r.stdout + r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert path in lines[0] and reason in lines[0], lines[0]


def leftovers(directory: Path) -> list[str]:
    """Temp files or directories a writer left behind (hidden ``.part`` names)."""
    return sorted(p.name for p in directory.rglob("*") if p.name.endswith(".part"))


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One small recording made by the real cell."""
    root = tmp_path_factory.mktemp("outputs")
    domain = next_domain()
    try:
        r = subprocess.run(
            [str(BIN / "winder"), "run", "--bag-dir", str(root / "bags"), *TINY, "--job-id", "outputs"],
            capture_output=True,
            text=True,
            timeout=300,
            stdin=subprocess.DEVNULL,
            env={**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
        )
    finally:
        release_domain(domain)
    assert r.returncode == 0, r.stdout + r.stderr
    (path,) = bags_in(root / "bags")
    return path


@pytest.fixture(scope="module")
def cut(bag: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bag's MCAP file cut short (before its summary, or inside its last
    chunk): a recording with whole messages to recover."""
    from winder.record.raw import BagError, read_raw

    (mcap,) = bag.glob("*.mcap")
    out = tmp_path_factory.mktemp("cut") / "cut.mcap"
    data = mcap.read_bytes()
    for frac in (0.95, 0.9, 0.8, 0.67, 0.5):
        out.write_bytes(data[: int(len(data) * frac)])
        try:
            if read_raw(out).recovered:
                return out
        except BagError:
            continue
    raise AssertionError(f"no cut of {mcap} leaves whole messages to recover")


# -- the helper --------------------------------------------------------------------------


def test_atomic_file_replaces_whole_or_leaves_the_file_as_it_was(tmp_path: Path) -> None:
    target = tmp_path / "table.json"
    target.write_text("old")
    os.chmod(target, 0o640)
    with pytest.raises(RuntimeError), atomic_file(target) as fh:
        fh.write("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old" and leftovers(tmp_path) == []
    write_text(target, "new")
    assert target.read_text() == "new" and (target.stat().st_mode & 0o777) == 0o640
    fresh = write_text(tmp_path / "sub" / "fresh.txt", "x")  # its directory made
    umask = os.umask(0)
    os.umask(umask)
    assert fresh.read_text() == "x" and (fresh.stat().st_mode & 0o777) == 0o666 & ~umask


def test_unwritable_paths_are_one_line_naming_the_path(tmp_path: Path) -> None:
    plain = tmp_path / "plain"
    plain.write_text("")
    with pytest.raises(OutputError, match=r"plain/x\.txt: cannot be made a directory: .*plain is a file"):
        write_text(plain / "x.txt" / "y", "x")
    with pytest.raises(OutputError, match=r"^/proc/winder\.txt: cannot be written: "):
        write_text("/proc/winder.txt", "x")
    with (
        pytest.raises(OutputError, match=r"^/proc/winder_dir: cannot be written: "),
        new_directory("/proc/winder_dir"),
    ):
        pass
    with pytest.raises(FileExistsError), new_directory(plain):
        pass


def test_new_directory_appears_whole_or_not_at_all(tmp_path: Path) -> None:
    out = tmp_path / "export"
    with pytest.raises(RuntimeError), new_directory(out) as work:
        (work / "a.csv").write_text("1\n")
        raise RuntimeError("interrupted")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with new_directory(out) as work:
        (work / "a.csv").write_text("1\n")
    assert (out / "a.csv").read_text() == "1\n" and [p.name for p in tmp_path.iterdir()] == ["export"]


# -- every command that writes ------------------------------------------------------------


@pytest.mark.ros
def test_unwritable_output_paths_of_every_command(bag: Path, cut: Path, tmp_path: Path) -> None:
    plain = tmp_path / "plain"
    plain.write_text("")
    job = tmp_path / "job.yaml"
    job.write_text("interp_node:\n  ros__parameters: {turns_per_layer: 4, layers: 1, poles: 1}\n")
    cases = [
        (["analyze", str(bag), "--plots-dir", f"{plain}/plots"], f"{plain}/plots", "plain is a file"),
        (["identify", str(bag), "--plots-dir", "/proc/winder_plots"], "/proc/winder_plots", "cannot be"),
        (["export", str(bag), "--csv", f"{plain}/csv"], str(plain), "is a file"),
        (["export", str(bag), "--csv", "/proc/winder_csv"], "/proc/winder_csv", "cannot be written"),
        (["figures", f"{plain}/figs"], f"{plain}/figs", "is a file"),
        (["resonance", "--linear-only", "--no-plots", "--zetas", "0.5", "--json", "/proc/w.json"],
         "/proc/w.json", "cannot be written"),
        (["tune", str(job), "--plots-dir", f"{plain}/tune"], f"{plain}/tune", "is a file"),
        (["bag", "recover", str(cut), "--output", f"{plain}/rec"], str(plain), "is a file"),
        (["bag", "recover", str(cut), "--output", "/proc/winder_rec"], "/proc/winder_rec",
         "cannot be written"),
    ]  # fmt: skip
    for args, path, reason in cases:
        assert_output_error(winder(*args, cwd=tmp_path), path, reason)
    assert leftovers(tmp_path) == []


@pytest.mark.ros
def test_a_full_disk_leaves_nothing_half_written(bag: Path, cut: Path, tmp_path: Path) -> None:
    """The kernel fails a write past 20 kB (EFBIG, as ENOSPC on a full disk):
    each command says so in one line and leaves no part of its output."""
    cases = [
        (["export", str(bag), "--csv", "csv"], "csv"),
        (["analyze", str(bag), "--plots-dir", "plots"], "plots/"),
        (["bag", "recover", str(cut), "--output", "rec"], "rec"),
        (["figures", "figs"], "figs/"),
    ]
    for args, path in cases:
        t0 = time.monotonic()
        r = winder(*args, cwd=tmp_path, fsize=20_000)
        assert_output_error(r, path, "File too large")
        assert time.monotonic() - t0 < 300
    assert not (tmp_path / "csv").exists() and not (tmp_path / "rec").exists()
    assert [p for p in (tmp_path / "plots").iterdir() if p.stat().st_size == 0] == []
    assert leftovers(tmp_path) == []
    # with room, the same commands write their files
    assert winder("export", str(bag), "--csv", "csv", cwd=tmp_path).returncode == 0
    assert (tmp_path / "csv" / "run.json").exists() and leftovers(tmp_path) == []
