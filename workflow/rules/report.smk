# Reports: a self-contained HTML page per trial and one per campaign.


rule report_trial:
    input:
        calibration="results/{campaign}/trial_{trial}/geometry.json",
        sync="results/{campaign}/trial_{trial}/clock.json",
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        tracking="results/{campaign}/trial_{trial}/tracking.json",
        video=trial_video,
        params="results/{campaign}/trial_{trial}/params.json",
        fit="results/{campaign}/trial_{trial}/fit.parquet",
        motion="results/{campaign}/trial_{trial}/motion.json",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_yaml,
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
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" report-trial --data-dir "data/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--results-dir "results/{wildcards.campaign}/trial_{wildcards.trial}" '
        '--campaign "{input.campaign}" --out "{output}"'


rule report_campaign:
    input:
        trial_reports,
        campaign=campaign_yaml,
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
        lab=campaign_lab_entries,
    shell:
        '{params.cli} --log "{log}" report-campaign --data-dir "data/{wildcards.campaign}" '
        '--results-dir "results/{wildcards.campaign}" --campaign "{input.campaign}" '
        '--out "{output}"'
