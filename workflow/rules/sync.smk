# Sync: the offset of the video's frames on the controller clock, from the arm seen in
# the video matched with the forward kinematics of the joint log.


rule sync:
    input:
        video=trial_video,
        frames="results/{campaign}/trial_{trial}/frames.npy",
        video_meta="data/{campaign}/trial_{trial}/video.yaml",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        calibration="results/{campaign}/trial_{trial}/calibration.json",
        campaign=campaign_for("sync"),
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
        lab=lab_entries_for("sync"),
    shell:
        '{params.cli} --log "{log}" sync --video "{input.video}" --video-meta "{input.video_meta}" '
        '--joints "{input.joints}" --calibration "{input.calibration}" --campaign "{input.campaign}" '
        '--out "{output}" --frames "{input.frames}" --workers {threads}'


# The arm's sweep: the swing plane's mapping and the clock refined together by the arm's
# links read across the trial (forward kinematics) and the board's corners.


rule sweep:
    input:
        video=trial_video,
        frames="results/{campaign}/trial_{trial}/frames.npy",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        calibration="results/{campaign}/trial_{trial}/calibration.json",
        sync="results/{campaign}/trial_{trial}/sync.json",
        campaign=campaign_for("sweep"),
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
        lab=lab_entries_for("sweep"),
    shell:
        '{params.cli} --log "{log}" sweep --video "{input.video}" --joints "{input.joints}" '
        '--calibration "{input.calibration}" --sync "{input.sync}" --campaign "{input.campaign}" '
        '--out-geometry "{output.geometry}" --out-clock "{output.clock}" --frames "{input.frames}" --workers {threads}'
