"""LP formulations: each gives a dense builder, a matrix-free operator and an evidence checker."""
