//! ROS wire formats (filled in).
