"""The closed loop: controllers, trajectories, disturbances, contact events, integration."""
