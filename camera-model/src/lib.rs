//! Pinhole cameras, poses, look-at, camera rigs and the PccAppRenderer-to-COLMAP transform.
