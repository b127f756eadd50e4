# Sync: the offset of the video's frames on the controller clock, from the arm seen in
# the video matched with the forward kinematics of the joint log.


rule sync:
    input:
        video=trial_video,
        meta="data/{campaign}/trial_{trial}/video.yaml",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        calibration="results/{campaign}/trial_{trial}/calibration.json",
        campaign="data/{campaign}/campaign.yaml",
    output:
        "results/{campaign}/trial_{trial}/sync.json",
    log:
        "results/{campaign}/logs/sync_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/sync_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("sync"),
        lab=campaign_lab_entries,
    shell:
        '{params.cli} sync --trial-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--calibration "{input.calibration}" --campaign "{input.campaign}" '
        '--out "{output}" > "{log}" 2>&1'
