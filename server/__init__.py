"""The sonarslam web service: REST and WebSocket API over the SLAM loop."""
