//! Viscoelastic restitution (paper Appendix A, spec section 2). Work in progress.
