"""The learned person detector: training data rendered by the simulator (dataset.py)."""
