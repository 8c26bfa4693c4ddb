//! Homogeneous clipping against the near and far planes (and guard band planes).
