//! The whole pipeline, input model to 3DGS model with a report, stage by stage.
