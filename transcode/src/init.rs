//! Splat initialisation: from the input's surface (with a closed-form SH fit) or from sparse points.
