//! TB6612FNG dual H-bridge driver (placeholder, filled in next).
