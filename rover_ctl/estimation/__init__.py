"""Pose estimation (pure core): typed sensor readings, the local ENU frame, the EKF."""
