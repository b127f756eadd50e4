# Markerless tracking: background, segmentation, skeleton, ordered from the grasp,
# resampled by arc length to the model's points, in the robot frame.


rule track:
    input:
        video=trial_video,
        frames="results/{campaign}/trial_{trial}/frames.npy",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        geometry="results/{campaign}/trial_{trial}/geometry.json",
        clock="results/{campaign}/trial_{trial}/clock.json",
        campaign=campaign_for("track"),
    output:
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        quality="results/{campaign}/trial_{trial}/tracking.json",
        overlay=report(
            "results/{campaign}/trial_{trial}/tracking_overlay.png",
            caption="../report/overlay.rst",
            category="Tracking",
        ),
    log:
        "results/{campaign}/logs/track_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/track_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 4  # worker processes over the decoded frames; capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("track"),
        lab=lab_entries_for("track"),
    shell:
        '{params.cli} --log "{log}" track --video "{input.video}" --joints "{input.joints}" '
        '--geometry "{input.geometry}" --clock "{input.clock}" --campaign "{input.campaign}" '
        '--out "{output.tracks}" --out-quality "{output.quality}" --overlay "{output.overlay}" '
        '--frames "{input.frames}" --workers {threads}'
