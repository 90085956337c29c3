"""hiros_pipeline: the stages composed in one process, offline over recordings and as a node."""

from hiros_pipeline.offline import RunSummary, run_recording
from hiros_pipeline.pipeline import STAGES, Pipeline, PipelineParams, StageOutputs

__all__ = ["STAGES", "Pipeline", "PipelineParams", "RunSummary", "StageOutputs", "run_recording"]
