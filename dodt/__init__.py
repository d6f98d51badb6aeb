"""DODT: dynamic-obstacle detection and tracking from RGB-D frames.

This package never imports ``sim`` or ``planner``: it runs unchanged on frames
recorded from a real camera.
"""
