# Motion generation (paper Section V): the first motion with Table 2's minimum
# parameters, then the next motion from each trial's estimate.


rule plan_first:
    input:
        campaign=campaign_for("plan-first"),
    output:
        csv="results/{campaign}/first_motion/motion.csv",
        json="results/{campaign}/first_motion/motion.json",
    log:
        "results/{campaign}/logs/plan_first.log",
    benchmark:
        "results/{campaign}/benchmarks/plan_first.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 8  # capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("plan-first"),
        lab=lab_entries_for("plan-first"),
    shell:
        'NUMBA_NUM_THREADS={threads} {params.cli} --log "{log}" plan-first --campaign "{input.campaign}" '
        '--out-dir "results/{wildcards.campaign}/first_motion"'


rule plan:
    input:
        params="results/{campaign}/trial_{trial}/params.json",
        played_motion="data/{campaign}/trial_{trial}/motion.json",
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_for("plan"),
    output:
        csv="results/{campaign}/trial_{trial}/motion.csv",
        json="results/{campaign}/trial_{trial}/motion.json",
    log:
        "results/{campaign}/logs/plan_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/plan_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 8  # capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("plan"),
        lab=lab_entries_for("plan"),
    shell:
        'NUMBA_NUM_THREADS={threads} {params.cli} --log "{log}" plan --params "{input.params}" --played-motion "{input.played_motion}" '
        '--tracks "{input.tracks}" --joints "{input.joints}" --campaign "{input.campaign}" --seed {wildcards.trial} '
        '--out-dir "results/{wildcards.campaign}/trial_{wildcards.trial}"'
