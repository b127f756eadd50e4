# Calibration: intrinsics from data/<campaign>/calib/ (if present; its board views found,
# and fitted on their own, once per campaign) and the pixel-to-plane homography from the
# ChArUco board in the trial's video.


rule calib_views:
    input:
        calib_dir="data/{campaign}/calib",
        campaign=campaign_for("calib-views"),
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
        lab=lab_entries_for("calib-views"),
    shell:
        '{params.cli} --log "{log}" calib-views --calib-dir "{input.calib_dir}" --campaign "{input.campaign}" '
        '--out "{output.views}" --out-intrinsics "{output.intrinsics}"'


rule calibrate:
    input:
        video=trial_video,
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_for("calibrate"),
        calib_views=calib_views_input,
        intrinsics=intrinsics_input,
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
        settings=stage_settings("calibrate"),
        lab=lab_entries_for("calibrate"),
    shell:
        '{params.cli} --log "{log}" calibrate --video "{input.video}" --joints "{input.joints}" '
        "--calib-views {input.calib_views:q} --intrinsics {input.intrinsics:q} "
        '--campaign "{input.campaign}" --out "{output}"'
