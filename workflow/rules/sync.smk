# Sync: the offset of the video's frames on the controller clock, from the arm seen in
# the video matched with the forward kinematics of the joint log.


rule sync:
    input:
        video=trial_video,
        frames="results/{campaign}/trial_{trial}/frames.npy",
        frames_meta="results/{campaign}/trial_{trial}/frames.json",
        meta="data/{campaign}/trial_{trial}/video.yaml",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        calibration="results/{campaign}/trial_{trial}/calibration.json",
        campaign=campaign_yaml,
    output:
        "results/{campaign}/trial_{trial}/sync.json",
    log:
        "results/{campaign}/logs/sync_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/sync_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 4  # worker processes over the decoded frames; capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("sync"),
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" sync --trial-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--calibration "{input.calibration}" --campaign "{input.campaign}" '
        '--out "{output}" --frames "{input.frames}" --workers {threads}'


# The arm's sweep: the swing plane's mapping and the clock refined together by the arm's
# links read across the trial (forward kinematics) and the board's corners.


rule sweep:
    input:
        video=trial_video,
        frames="results/{campaign}/trial_{trial}/frames.npy",
        frames_meta="results/{campaign}/trial_{trial}/frames.json",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        calibration="results/{campaign}/trial_{trial}/calibration.json",
        sync="results/{campaign}/trial_{trial}/sync.json",
        campaign=campaign_yaml,
    output:
        geometry="results/{campaign}/trial_{trial}/geometry.json",
        clock="results/{campaign}/trial_{trial}/clock.json",
    log:
        "results/{campaign}/logs/sweep_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/sweep_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 2  # worker processes over its 40 frames; capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("sweep"),
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" sweep --trial-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--calibration "{input.calibration}" --sync "{input.sync}" --campaign "{input.campaign}" '
        '--out-geometry "{output.geometry}" --out-clock "{output.clock}" --frames "{input.frames}" --workers {threads}'
