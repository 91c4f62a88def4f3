"""The application shell: scenario files, runs and their results, plots, replay, the CLI."""
