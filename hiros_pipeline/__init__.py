"""hiros_pipeline: the stages composed in one process, offline over recordings and as a node."""

from hiros_pipeline.offline import RunSummary, run_recording
from hiros_pipeline.params import OFFLINE_MERGE_RATE, load_pipeline_params
from hiros_pipeline.pipeline import STAGES, Pipeline, PipelineParams, StageOutputs

__all__ = [
    "OFFLINE_MERGE_RATE",
    "STAGES",
    "Pipeline",
    "PipelineParams",
    "RunSummary",
    "StageOutputs",
    "load_pipeline_params",
    "run_recording",
]
