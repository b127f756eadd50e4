# stringcast workflow: raw trial files under data/ -> results/ (docs/data_contract.md).
# One campaign = one string and target; each trial_<k> is one execution.
#   snakemake -n                                        # what would run
#   snakemake --cores 2 results/demo/trial_1/tracks.parquet   # one stage of one trial
# The rules are thin: each calls one `stringcast` subcommand; the logic lives in
# src/stringcast/ and is tested without Snakemake.
from snakemake.exceptions import WorkflowError
from snakemake.utils import min_version

from stringcast.core import ConfigError, merge_config, typed_overrides, validate

min_version("8.0")


configfile: "config/config.yaml"


# --config 'SECTION={KEY: VALUE}' sets settings, typed as in a config file
merge_config(config, typed_overrides(workflow.config_settings.config))
# the lab's sections (workflow/schemas/config.schema.json) and the stages' (from their settings classes)
try:
    validate(
        {k: v for k, v in config.items() if k != "_path"},
        "config.schema.json",
        "the workflow's config",
    )
except ConfigError as exc:
    raise WorkflowError(f"stringcast: {exc}") from exc


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/plan.smk"
include: "workflow/rules/video.smk"
include: "workflow/rules/calibrate.smk"
include: "workflow/rules/sync.smk"
include: "workflow/rules/track.smk"
include: "workflow/rules/estimate.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input:
        all_targets,


# A campaign whose raw files have errors is not built (workflow/rules/common.smk: checked);
# this job runs after every other and fails, listing them, so the run ends non-zero.
rule refused_campaigns:
    input:
        campaign_targets,
    output:
        REFUSED,
    log:
        "results/logs/refused_campaigns.log",
    conda:
        "workflow/envs/stringcast.yaml"
    params:
        report=refused_report,
    shell:
        "printf '%s\\n' {params.report} | tee {log} >&2; exit 1"
