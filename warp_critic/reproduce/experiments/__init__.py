"""Experiments: the paper's stages -- settings, recipes, validation, the plan and each stage's function."""
