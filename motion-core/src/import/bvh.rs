//! BVH motion-capture import.
