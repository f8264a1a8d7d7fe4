//! The shared render library: camera rays, lights and their sampling, surface interaction, the
//! path-tracing integrator core, and the film that assembles images from per-pixel samples.
//! The reference renderers, point-based GI and the pipelines to come build on it; it is a
//! library only: no node lives here.
//!
//! - `bidir`: the bidirectional path tracer (camera and light subpaths joined under MIS).
//! - `camera`: primary rays of the scene camera and its importance.
//! - `lights`: choosing and sampling lights for next-event estimation.
//! - `surface`: the surface point a ray hit (position, normals, object).
//! - `integrator`: the unidirectional path tracer (`Tracer::radiance`) and its settings.
//! - `zbuffer`: the primary hits of a pinhole camera by projecting triangles instead of
//!   tracing rays (a sample pattern, near clipping, perspective-correct barycentrics).
//! - `film`: per-pixel loops over an image (rows in parallel, with progress and
//!   cancellation) and the accumulation of progressive passes into mean and variance.

pub mod bidir;
pub mod camera;
pub mod film;
pub mod integrator;
pub mod lights;
pub mod surface;
pub mod zbuffer;
