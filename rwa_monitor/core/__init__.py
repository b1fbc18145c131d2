"""Pure numpy/scipy algorithms and models: no ROS, no file I/O."""
