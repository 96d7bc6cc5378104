//! Evaluation of a trained model against reference views: image metrics, masks, distance to the surface.
