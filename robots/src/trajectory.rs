//! Desired trajectories (Laut 2011 Appendix A). (being written)
