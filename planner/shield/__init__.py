"""Passive safety around any planner (shield.PassiveSafetyShield): the check of motions that end at rest
(safety) and the alternative motions it flies when a plan is not safe (candidates)."""
