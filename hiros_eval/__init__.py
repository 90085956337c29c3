"""hiros_eval: accuracy figures of the pipeline against the truth (simulator or mocap)."""
