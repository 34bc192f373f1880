//! # shelldsa
//!
//! Design sensitivity analysis of finite-deformation elastoplastic shells, discretised meshfree on
//! CAD surfaces, with frictionless rigid-tool contact (Choi, Yi, Kim, Botkin, DETC 2003). Every
//! derivative is computable three ways: the hand-derived continuum method, a dual-number reference
//! through the same generic kernels, and finite differences ([`verification`]).

#[macro_use]
mod wide;

pub mod cli;
pub mod contact;
pub mod geometry;
pub mod io;
pub mod kinematics;
pub mod material;
pub mod meshfree;
pub mod scalar;
pub mod sensitivity;
pub mod shell;
pub mod solver;
pub mod verification;

pub use scalar::Real;
