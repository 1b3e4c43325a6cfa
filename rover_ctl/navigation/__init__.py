"""Navigation (pure core): global planner, obstacle memory, fuzzy navigator, wheel-speed control."""
