"""Path planners compared with the DRL policy: sampling-based planners in joint space."""
