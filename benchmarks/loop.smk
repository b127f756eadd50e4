# The loop benchmark's campaigns as separate jobs (benchmarks/loop.py): one job per
# campaign (string type x seed x method), side by side or on a cluster, then one job that
# gathers their run.json files into results/bench/loop.json.
#   snakemake -s benchmarks/loop.smk --cores 8 --config work=/data/loop
#   snakemake -s benchmarks/loop.smk --profile config/profiles/slurm --config work=/shared/loop
# work (required): where the campaigns live (reused: a finished campaign is not run again);
# types, seeds, methods: space-separated lists (default: 1-7, 0 1 2, paper ours);
# campaign_cores: each campaign's Snakemake --cores (default 2). The jobs run in the
# repository (benchmarks/ is not an installed package); loop.json goes to results/bench/ there,
# or to $STRINGCAST_BENCH_DIR.


import os
import sys

if "work" not in config:
    raise ValueError(
        "benchmarks/loop.smk: give the campaigns' folder: --config work=DIR"
    )
WORK = Path(str(config["work"])).resolve()
TYPES = str(config.get("types", "1 2 3 4 5 6 7")).split()
SEEDS = str(config.get("seeds", "0 1 2")).split()
METHODS = str(config.get("methods", "paper ours")).split()
CORES = int(config.get("campaign_cores", 2))
PY = sys.executable
REPO = Path(workflow.basedir).parent
BENCH = Path(
    os.environ.get("STRINGCAST_BENCH_DIR") or REPO / "results" / "bench"
).resolve()


wildcard_constraints:
    type=r"\d+",
    seed=r"\d+",
    method=r"[a-z]+",


rule all:
    input:
        f"{BENCH}/loop.json",


rule campaign:
    output:
        f"{WORK}/loop_s{{type}}_seed{{seed}}_{{method}}/run.json",
    log:
        f"{WORK}/logs/loop_s{{type}}_seed{{seed}}_{{method}}.log",
    threads: CORES
    resources:
        runtime=600,
        mem_mb=6000,
        cpus_per_task=CORES,
    shell:
        'cd "{REPO}" && "{PY}" -m benchmarks.loop --only {wildcards.type} {wildcards.seed} {wildcards.method} '
        '--work "{WORK}" --cores {threads} > "{log}" 2>&1'


rule gather:
    input:
        expand(
            f"{WORK}/loop_s{{type}}_seed{{seed}}_{{method}}/run.json",
            type=TYPES,
            seed=SEEDS,
            method=METHODS,
        ),
    output:
        f"{BENCH}/loop.json",
    shell:
        'cd "{REPO}" && "{PY}" -m benchmarks.loop --finished-only --work "{WORK}" --types {TYPES} '
        "--seeds {SEEDS} --methods {METHODS}"
