//! Marble–board narrow phase: which board pieces a marble touches, and when along its path
//! it first reaches a piece it does not touch yet.
//!
//! # Touching
//! A marble of radius `r` centred at `x` touches a convex piece when the signed distance
//! from `x` to the piece's surface is at most `r + tol` (`tol`: the touching tolerance,
//! [`StepConfig::contact_tolerance`](crate::config::StepConfig) × r plus the f32 resolution
//! of `x`). A marble can touch several pieces; the [`TouchList`] filter keeps only those
//! that constrain it independently: a candidate whose closest point lies on or behind the
//! tangent plane of a nearer accepted contact is implied by that contact (a marble pushed
//! out of the nearer plane is also out of a point behind it). That removes the spurious
//! edge normals of coplanar seams between boards or triangles and of convex ridges, the
//! "ghost bumps" other engines suffer on meshes, while a concave corner (floor and wall)
//! keeps both contacts.
//!
//! # Time of impact
//! Continuous collision asks, for each piece the marble does not yet touch, the first time
//! `τ` in the substep at which `d(τ) = dist(x(τ), piece(τ)) − r` falls within the touching
//! tolerance, where `x(τ)` is the marble's path (the parabola of constant acceleration every
//! integrator follows, see [`Integrator`](crate::config::Integrator)) and the piece moves
//! with its board (translation and rotation). It uses **conservative advancement**: if
//! `|ḋ| ≤ L` on the interval, no root lies before `τ + (d − tol/4)/L`, so stepping by that
//! amount never passes an impact; the search stops within `tol/2`, so that the touch
//! gathered at the impact with the full tolerance includes the piece despite rounding. The
//! bound `L` is the marble's speed bound along its path; for a moving board, the marble's
//! speed relative to the board's material point under it (small for marbles riding a
//! turning board); and where every centre the marble can reach has its closest point on
//! one flat face (a plane, or a box face), only the normal part of that relative motion, so
//! a marble sliding just above a surface does not make the advancement crawl. A head-on
//! approach converges in one or two iterations; grazing approaches converge geometrically.
//! Because each step is safe, a marble at any speed never passes through a board, however
//! thin.
//!
//! # Near pieces
//! Most marbles spend most substeps far from everything but the piece they roll on. Each
//! marble keeps a [`NearPieces`] list (a Verlet list, or "skin", for board pieces): the
//! pieces of one board within a few radii of where the list was built, in the board's
//! frame. While the marble stays within the list's reach of that spot of the board, its
//! touches and impacts need only the listed pieces — the same answers, bit for bit, as a
//! search of the board (the pieces keep the search's order) — and detection rebuilds the
//! list when the marble leaves it. When the list holds one piece of a still board and
//! nothing else is within reach of the marble's substep, it gives the touch directly
//! ([`NearPieces::lone_touch`]; in closed form over a flat face), and a marble resting or
//! sliding there is resolved in closed form ([`crate::response::resolve_resting`]; a
//! spinning one by the event loop on that one touch): no search at all in the commonest
//! case. On the scene's only board, moving or still, the list answers the searches of a
//! marble riding it, on one piece or several ([`crate::response::resolve_riding`]), while
//! it covers the marble's path.

use std::sync::Arc;

use bevy_ecs::prelude::*;
use glam::{Quat, Vec3};
use parry3d::bounding_volume::Aabb;

use crate::geometry::{AabbTransform, BoardGeometry, Piece, PieceId};

mod ccd;
mod near;
mod snapshot;
mod touch;

pub use ccd::{Path, earliest_impact};
pub(crate) use ccd::{path_is_clear, touched_path_is_clear};
pub use near::{NEAR_MAX, NearPieces};
pub use snapshot::{BoardCache, BoardSnapshot};
pub use touch::{MAX_TOUCHES, Material, Touch, TouchList, gather, touch_tolerance};
pub(crate) use touch::{gather_board, gather_single};
use touch::{overlaps, sphere_aabb};

#[cfg(test)]
mod tests;
