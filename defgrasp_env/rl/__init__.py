"""Reinforcement-learning integrations of the native vector env (optional extra ``defgrasp[rl]``)."""
