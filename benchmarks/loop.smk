# The loop benchmark's campaigns as separate jobs (benchmarks/loop.py): one job per
# campaign (physics x mode x string type x seed x method), side by side or on a cluster,
# then one job that gathers their run.json files into results/bench/loop.json.
#   snakemake -s benchmarks/loop.smk --cores 8 --config work=/data/loop
#   snakemake -s benchmarks/loop.smk --profile config/profiles/slurm --config work=/shared/loop
# work (required): where the campaigns live (reused: a finished campaign is not run again);
# types, seeds, methods, physics: space-separated lists (default: 1-7, 0 1 2 3 4, paper ours,
# mujoco elastica); mode: state (default) or video; in the state mode the video check's
# video_types (default: types), video_seeds (default 0; "" for none) and video_methods
# (default ours); state_source: the folder with tracking.json and generalization.json
# (default results/bench/ in the repository); campaign_cores: each campaign's Snakemake
# --cores (default 2); family=true: each seed also draws the lab's string material (loop.json's
# family entry; benchmarks/loop.py). Where the gathered file (loop.json, or loop_family.md) exists
# already, Snakemake finds nothing to do: add --forcerun gather to run new campaigns. The jobs run
# in the repository (benchmarks/ is not an installed package); loop.json goes to results/bench/
# there, or to $STRINGCAST_BENCH_DIR. With a variant of ours among the methods (an A/B, e.g.
# methods=ours_grasp_flip) the run ends with the campaigns' run.json: pair them with benchmarks.loop_ab.


import os
import sys

if "work" not in config:
    raise ValueError(
        "benchmarks/loop.smk: give the campaigns' folder: --config work=DIR"
    )
WORK = Path(str(config["work"])).resolve()


def words(key, default):
    """A --config list as words; Snakemake reads key="" as None (none) and key=3 as an int."""
    value = config.get(key, default)
    return [] if value is None else str(value).split()


TYPES = words("types", "1 2 3 4 5 6 7")
SEEDS = words("seeds", "0 1 2 3 4")
METHODS = words("methods", "paper ours")
PHYSICS = words("physics", "mujoco elastica")
MODE = str(config.get("mode", "state"))
VIDEO_TYPES = words("video_types", " ".join(TYPES))
VIDEO_SEEDS = words("video_seeds", "0") if MODE == "state" else []
VIDEO_METHODS = words("video_methods", "ours")
CORES = int(config.get("campaign_cores", 2))
FAMILY = str(config.get("family", "false")).lower() in ("1", "true", "yes")
FAMILY_ARG = "--family" if FAMILY else ""
FAMILY_TAG = "family_" if FAMILY else ""
# a family run's own product (it adds loop.json's family entry, which a finished main run's loop.json
# would otherwise already stand for)
GATHERED = "loop_family.md" if FAMILY else "loop.json"
PY = sys.executable
REPO = Path(workflow.basedir).parent
BENCH = Path(
    os.environ.get("STRINGCAST_BENCH_DIR") or REPO / "results" / "bench"
).resolve()
STATE_SOURCE = Path(
    str(config.get("state_source", REPO / "results" / "bench"))
).resolve()
RUN = f"{WORK}/loop_{FAMILY_TAG}{{physics}}_{{mode}}_s{{type}}_seed{{seed}}_{{method}}/run.json"
RUNS = expand(
    RUN, physics=PHYSICS, mode=[MODE], type=TYPES, seed=SEEDS, method=METHODS
) + expand(
    RUN,
    physics=PHYSICS,
    mode=["video"],
    type=VIDEO_TYPES,
    seed=VIDEO_SEEDS,
    method=VIDEO_METHODS,
)
sys.path.insert(0, str(REPO))  # benchmarks/ is not an installed package
from benchmarks.loop_methods import METHODS as GATHERED_METHODS

# A variant of ours (benchmarks/loop_methods.py VARIANTS) is an A/B left out of loop.json: such a run
# ends with its campaigns' run.json, to pair with benchmarks.loop_ab, and gathers nothing.
VARIANT_RUN = any(m not in GATHERED_METHODS for m in METHODS + VIDEO_METHODS)


wildcard_constraints:
    physics=r"[a-z]+",
    mode=r"state|video",
    type=r"\d+",
    seed=r"\d+",
    method=r"[a-z_]+",


rule all:
    input:
        RUNS if VARIANT_RUN else f"{BENCH}/{GATHERED}",


rule campaign:
    output:
        RUN,
    log:
        f"{WORK}/logs/loop_{FAMILY_TAG}{{physics}}_{{mode}}_s{{type}}_seed{{seed}}_{{method}}.log",
    threads: CORES
    resources:
        runtime=600,
        mem_mb=6000,
        cpus_per_task=CORES,
    shell:
        'cd "{REPO}" && "{PY}" -m benchmarks.loop --only {wildcards.type} {wildcards.seed} {wildcards.method} '
        '--physics {wildcards.physics} --mode {wildcards.mode} --state-source "{STATE_SOURCE}" '
        '--work "{WORK}" --cores {threads} {FAMILY_ARG} > "{log}" 2>&1'


rule gather:
    input:
        RUNS,
    output:
        f"{BENCH}/{GATHERED}",
    params:
        video=(
            f"--video-types {' '.join(VIDEO_TYPES)} --video-methods {' '.join(VIDEO_METHODS)} "
            f"--video-seeds {' '.join(VIDEO_SEEDS)}"
        ),
    shell:
        'cd "{REPO}" && "{PY}" -m benchmarks.loop --finished-only --work "{WORK}" --types {TYPES} '
        "--seeds {SEEDS} --methods {METHODS} --physics {PHYSICS} --mode {MODE} {params.video} "
        '--state-source "{STATE_SOURCE}" {FAMILY_ARG}'
