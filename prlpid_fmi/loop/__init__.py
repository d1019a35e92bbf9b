"""The closed loop: the loop core (plant FMU, prior, PID, reward), the agent's action path (gain maps, the Gymnasium
env), the reward forecast, crash isolation, and rollouts that measure it."""
