# Parameter estimation: the model driven by the measured joints, fitted to the
# tracked points (E of eqs. 4-6; search of eqs. 2-3).


rule estimate:
    input:
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        # the earlier stages' verdicts, carried into the fit's
        geometry="results/{campaign}/trial_{trial}/geometry.json",
        clock="results/{campaign}/trial_{trial}/clock.json",
        tracking="results/{campaign}/trial_{trial}/tracking.json",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_for("estimate"),
        prev=previous_params,
    output:
        params="results/{campaign}/trial_{trial}/params.json",
        fit="results/{campaign}/trial_{trial}/fit.parquet",
    log:
        "results/{campaign}/logs/estimate_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/estimate_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    threads: 8  # capped at --cores when run locally
    params:
        cli=CLI,
        settings=stage_settings("estimate"),
        lab=lab_entries_for("estimate"),
    shell:
        'NUMBA_NUM_THREADS={threads} {params.cli} --log "{log}" estimate --tracks "{input.tracks}" '
        '--joints "{input.joints}" --campaign "{input.campaign}" --prev {input.prev:q} '
        '--geometry "{input.geometry}" --clock "{input.clock}" --tracking "{input.tracking}" '
        '--trial {wildcards.trial} --out-params "{output.params}" --out-fit "{output.fit}"'


# The next-motion prediction error (issue 27): trial k - 1's estimate driven by this trial's
# measured joints, its tip against this trial's tracked tip (out-of-sample validation).


rule predict:
    input:
        params=predicting_params,
        tracks="results/{campaign}/trial_{trial}/tracks.parquet",
        joints="data/{campaign}/trial_{trial}/joints.csv",
        campaign=campaign_for("predict"),
    output:
        "results/{campaign}/trial_{trial}/prediction.json",
    log:
        "results/{campaign}/logs/predict_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/predict_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("predict"),
        lab=lab_entries_for("predict"),
    shell:
        '{params.cli} --log "{log}" predict --params "{input.params}" --tracks "{input.tracks}" --joints "{input.joints}" '
        '--campaign "{input.campaign}" --out "{output}"'
