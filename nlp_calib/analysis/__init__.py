"""Analysis layer: what a result is worth: trajectory metrics, uncertainty, observability, odometry,
time alignment and encoder faults."""
