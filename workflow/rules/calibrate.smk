# Calibration: intrinsics from data/<campaign>/calib/ (if present; its board views found,
# and fitted on their own, once per campaign) and the pixel-to-plane homography from the
# ChArUco board in the trial's video.


rule calib_views:
    input:
        calib="data/{campaign}/calib",
        campaign=campaign_yaml,
    output:
        views="results/{campaign}/calib_views.npz",
        intrinsics="results/{campaign}/intrinsics.json",
    log:
        "results/{campaign}/logs/calib_views.log",
    benchmark:
        "results/{campaign}/benchmarks/calib_views.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("calib-views"),
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" calib-views --calib-dir "{input.calib}" --campaign "{input.campaign}" '
        '--out "{output.views}" --out-intrinsics "{output.intrinsics}"'


rule calibrate:
    input:
        video=trial_video,
        meta="data/{campaign}/trial_{trial}/video.yaml",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_yaml,
        calib=calib_input,
    output:
        "results/{campaign}/trial_{trial}/calibration.json",
    log:
        "results/{campaign}/logs/calibrate_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/calibrate_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        calib=calib_arg,
        settings=stage_settings("calibrate"),
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" calibrate --trial-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '{params.calib} --campaign "{input.campaign}" --out "{output}"'
