"""The edge where the models, the simulation and the metrics meet: evaluations."""
