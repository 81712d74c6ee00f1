//! Discrete operators on triangle and tetrahedral meshes, matching libigl's conventions:
//! cotangent Laplacian ([`cotan_laplacian`], `igl::cotmatrix`), lumped mass matrices
//! ([`massmatrix`], `igl::massmatrix`), the biharmonic energy matrix
//! `B = L^T M^-1 L` ([`biharmonic_matrix`], Solomon & Stein 2025 Sec. 7), element measures and
//! validation ([`element_measures`], [`check_elements`]) and vertex components
//! ([`connected_components`]).
//!
//! Per-element work runs in parallel with rayon; assembly is deterministic.

mod biharmonic;
mod components;
mod cotan;
mod elements;
mod mass;

pub use biharmonic::{biharmonic_from_parts, biharmonic_matrix, scaled_inverse_masses};
pub use components::connected_components;
pub use cotan::cotan_laplacian;
pub use elements::{check_elements, element_measures};
pub use mass::{massmatrix, MassKind};
