"""Agents: the baselines, PPO policies (shipped and saved), and the one episode loop."""
