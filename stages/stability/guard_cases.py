"""Training guards: a non-finite loss or gradient skips the step, says which term and where, stops after N."""
