"""The autopilot (pure core): modes, mission executor, failsafes and the decision step."""
