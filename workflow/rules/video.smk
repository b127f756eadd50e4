# The trial's video decoded once into frames.npy (+ frames.json), read by sync, the sweep
# and tracking instead of each decoding the video again. Kept, not temp(): a temp file
# needed again (a tracking setting changed) would be decoded again and rerun sync and the
# sweep, which read it. It is F x H x W bytes (8-bit video); deleting it reruns the trial.


rule decode:
    input:
        video=trial_video,
    output:
        frames="results/{campaign}/trial_{trial}/frames.npy",
        meta="results/{campaign}/trial_{trial}/frames.json",
    log:
        "results/{campaign}/logs/decode_{trial}.log",
    benchmark:
        "results/{campaign}/benchmarks/decode_{trial}.tsv"
    conda:
        "../envs/stringcast.yaml"
    params:
        cli=CLI,
        settings=stage_settings("decode"),
    shell:
        '{params.cli} --log "{log}" decode --video "{input.video}" --out "{output.frames}"'
