# Reports: a self-contained HTML page per trial and one per campaign.


rule report_trial:
    input:
        geometry="results/{campaign}/trial_{trial}/geometry.json",
        clock="results/{campaign}/trial_{trial}/clock.json",
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        tracking="results/{campaign}/trial_{trial}/tracking.json",
        video=trial_video,
        params="results/{campaign}/trial_{trial}/params.json",
        fit="results/{campaign}/trial_{trial}/fit.parquet",
        next_motion="results/{campaign}/trial_{trial}/motion.csv",
        next_motion_meta="results/{campaign}/trial_{trial}/motion.json",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        played_motion="data/{campaign}/trial_{trial}/motion.json",
        prediction=prediction_input,
        campaign=campaign_for("report-trial"),
    output:
        report(
            "results/{campaign}/trial_{trial}/report.html",
            caption="../report/trial.rst",
            category="Trials",
        ),
    log:
        "results/{campaign}/logs/report_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/report_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("report-trial"),
        lab=lab_entries_for("report-trial"),
    shell:
        '{params.cli} --log "{log}" report-trial --video "{input.video}" --joints "{input.joints}" '
        '--played-motion "{input.played_motion}" --geometry "{input.geometry}" --clock "{input.clock}" '
        '--tracks "{input.tracks}" --tracking "{input.tracking}" --params "{input.params}" --fit "{input.fit}" '
        '--next-motion "{input.next_motion}" --next-motion-meta "{input.next_motion_meta}" '
        "--prediction {input.prediction:q} "
        '--campaign "{input.campaign}" --out "{output}"'


rule report_campaign:
    input:
        trial_reports,
        campaign=campaign_for("report-campaign"),
    output:
        report(
            "results/{campaign}/report.html",
            caption="../report/campaign.rst",
            category="Campaigns",
        ),
    log:
        "results/{campaign}/logs/report_campaign.log",
    benchmark:
        "results/{campaign}/benchmarks/report_campaign.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("report-campaign"),
        lab=lab_entries_for("report-campaign"),
    shell:
        '{params.cli} --log "{log}" report-campaign --data-dir "data/{wildcards.campaign}" '
        '--results-dir "results/{wildcards.campaign}" --campaign "{input.campaign}" '
        '--out "{output}"'
