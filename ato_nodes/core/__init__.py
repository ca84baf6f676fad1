"""ROS-free algorithms and configuration, in rooms (docs/architecture.md): base,
optimizers, train, scoring, control, targets, config, run; each imports only those
before it."""
