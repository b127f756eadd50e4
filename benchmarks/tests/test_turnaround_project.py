"""benchmarks/turnaround: the benchmark's project runs this checkout's workflow, whatever its --work held."""
from benchmarks.turnaround import ROOT, _project


def test_links_left_by_another_checkout_are_pointed_here_again(tmp_path):
    """A --work folder made by another worktree (its links now dangling, or to that worktree's workflow)
    would time that checkout's Snakefile with this one's code, or fail: the links are made anew."""
    root = tmp_path / "project"
    root.mkdir()
    (root / "Snakefile").symlink_to(tmp_path / "gone" / "Snakefile")        # dangling
    (root / "workflow").symlink_to(tmp_path)                               # another checkout's
    assert _project(tmp_path) == root
    for name in ("Snakefile", "workflow", "config"):
        assert (root / name).readlink() == ROOT / name and (root / name).exists()
