"""Training, evaluation, export and loading of FR5 policies (Stable-Baselines3)."""
