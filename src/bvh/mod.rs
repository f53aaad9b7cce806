//! The refittable bounding-volume hierarchy over rigid bodies.
