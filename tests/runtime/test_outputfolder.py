"""The output folder keeps whole runs only: checked before any work, replaced whole, never mixed,
left as it was by a run that fails, and held by one run at a time."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from folder_helpers import earlier_run, listing

from orthosim.runtime.outputfolder import OutputFolderError, clear_leftovers, output_folder

ROOT = Path(__file__).resolve().parents[2]


def test_a_rerun_replaces_the_earlier_run_whole_with_no_stale_frames_or_temporary_files(tmp_path):
    out = tmp_path / "out"
    earlier_run(out, frames=10)
    with output_folder(out) as staging:
        (staging / "frames").mkdir()
        for i in range(3):
            (staging / "frames" / f"{i:05d}.png").write_bytes(b"new")
        (staging / "run.json").write_text('{"complete": true, "new": true}')
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["00000.png", "00001.png", "00002.png"]
    assert not (out / "metrics.json").exists()  # the earlier run's, not written by this one
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging, old copy or lock left


def test_a_run_that_fails_part_way_leaves_the_earlier_run_as_it_was(tmp_path):
    out = tmp_path / "out"
    earlier_run(out, frames=4)
    before = listing(out)
    with pytest.raises(RuntimeError, match="half way"):
        with output_folder(out) as staging:
            (staging / "frames").mkdir()
            (staging / "frames" / "00000.png").write_bytes(b"new")
            raise RuntimeError("stopped half way")
    assert listing(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_run_that_fails_into_a_new_folder_leaves_no_folder(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with output_folder(tmp_path / "new") as staging:
            (staging / "metrics.json").write_text("{}")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_an_existing_file_as_out_is_refused_in_one_line(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text("{}")
    with pytest.raises(OutputFolderError, match="is a file, not a folder"):
        with output_folder(target):
            pytest.fail("the run must not start")


def test_a_folder_no_run_wrote_is_refused_rather_than_replaced(tmp_path):
    (tmp_path / "thesis.docx").write_text("months of work")
    with pytest.raises(OutputFolderError, match="thesis.docx"):
        with output_folder(tmp_path):
            pytest.fail("the run must not start")
    assert (tmp_path / "thesis.docx").read_text() == "months of work"


def test_a_second_run_into_the_same_folder_is_refused_while_the_first_holds_it(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from orthosim.runtime.outputfolder import output_folder
        with output_folder({str(out)!r}) as staging:
            print("holding", flush=True)
            sys.stdin.readline()
            (staging / "run.json").write_text("{{}}")
        """)], cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "holding"
        with pytest.raises(OutputFolderError, match=rf"another orthosim run \(pid {holder.pid}\) is writing this folder"):
            with output_folder(out):
                pytest.fail("the second run must not start")
        holder.stdin.write("\n")
        holder.stdin.flush()
        assert holder.wait(timeout=30) == 0
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()
    assert (out / "run.json").read_text() == "{}"  # the first run finished whole
    with output_folder(out) as staging:  # and the folder is free again
        (staging / "run.json").write_text("{}")


def test_what_a_killed_run_left_beside_the_folder_is_cleared_by_the_next_run(tmp_path):
    out = tmp_path / "out"
    stale = tmp_path / ".out.orthosim-staging-999999"
    (stale / "frames").mkdir(parents=True)
    with output_folder(out) as staging:
        (staging / "run.json").write_text("{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_an_out_folder_on_a_read_only_file_system_is_refused_before_any_work(read_only_folder):
    with pytest.raises(OutputFolderError, match="Read-only file system"):
        with output_folder(read_only_folder / "run"):
            pytest.fail("the run must not start")


def test_a_full_disk_is_one_line_and_leaves_the_earlier_run_as_it_was(tiny_disk):
    out = tiny_disk / "out"
    earlier_run(out, frames=2)
    before = listing(out)
    with pytest.raises(OutputFolderError, match="No space left on device.*left as it was"):
        with output_folder(out) as staging:
            (staging / "frames").mkdir()
            for i in range(100):
                (staging / "frames" / f"{i:05d}.png").write_bytes(os.urandom(32 * 1024))
    assert listing(out) == before
    assert sorted(p.name for p in tiny_disk.iterdir()) == ["out"]


def test_a_case_file_kept_in_its_run_folder_is_carried_into_the_new_run(tmp_path):
    """`orthosim batch` writes each variant's case.toml into its run folder, then runs it there."""
    from orthosim.runtime.outputfolder import output_folder

    target = tmp_path / "run"
    target.mkdir()
    (target / "case.toml").write_text("[model]\n")
    with output_folder(target, carry=("case.toml",)) as staging:
        (staging / "metrics.json").write_text("{}")
    assert sorted(p.name for p in target.iterdir()) == ["case.toml", "metrics.json"]
    assert (target / "case.toml").read_text() == "[model]\n"


def test_what_a_kill_during_the_swap_left_beside_a_finished_folder_is_cleared_without_running_again(tmp_path):
    out = tmp_path / "out"
    with output_folder(out) as staging:
        (staging / "run.json").write_text("{}")
    (tmp_path / ".out.orthosim-old-4242" / "frames").mkdir(parents=True)  # the earlier copy, not yet deleted
    (tmp_path / ".out.orthosim-lock").write_text("4242\n")  # its lock file, never unlinked
    clear_leftovers(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert (out / "run.json").read_text() == "{}"  # the finished run itself untouched
