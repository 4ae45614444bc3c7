"""Post-processing of contact maps: morphology statistics (:mod:`vecontact.analysis.morphology`)."""
