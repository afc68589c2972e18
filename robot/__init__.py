"""sonarslam: sonar occupancy-grid SLAM with Kalman dead reckoning and BOB-style exploration."""

__version__ = "0.1.0"
