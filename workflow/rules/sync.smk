# Sync: the offset of the video's frames on the controller clock.


rule sync:
    input:
        meta="data/{campaign}/trial_{trial}/video.yaml",
        joints="data/{campaign}/trial_{trial}/joints.csv",
    output:
        "results/{campaign}/trial_{trial}/sync.json",
    params:
        cli=CLI,
    benchmark:
        "results/{campaign}/benchmarks/sync_{trial}.tsv",
    log:
        "results/{campaign}/logs/sync_{trial}.log",
    shell:
        '{params.cli} sync --trial-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--out "{output}" > "{log}" 2>&1'
