//! Differentiable neural-network building blocks (owned by the model work).
