//! The boards as one substep sees them: each board's pose and motion, and the cache of
//! them.

use super::*;

/// A board as seen by one substep: its pose at the substep's start and its motion.
#[derive(Clone, Debug)]
pub struct BoardSnapshot {
    /// The board entity.
    pub entity: Entity,
    /// Its shape.
    pub geometry: Arc<BoardGeometry>,
    /// Origin at the substep's start, world.
    pub position: Vec3,
    /// Orientation at the substep's start.
    pub rotation: Quat,
    /// Linear velocity, m/s.
    pub velocity: Vec3,
    /// Angular velocity about `position`, rad/s, world.
    pub angular_velocity: Vec3,
    /// Restitution.
    pub restitution: f32,
    /// Friction.
    pub friction: f32,
    /// Rolling resistance coefficient (used when rolling is on).
    pub rolling_resistance: f32,
    /// Spin damping coefficient (used when rolling is on).
    pub spin_damping: f32,
    /// World bounds swept over the substep; `None` when unbounded (planes).
    pub swept_aabb: Option<Aabb>,
    /// Farthest distance of the board's bounds from its origin (for rotation bounds).
    pub reach: f32,
    /// Changes whenever the board's pose at a substep's start differs from the last
    /// substep's (set by the prepare stage).
    pub pose_version: u32,
    /// The substep's length and [`BoardSnapshot::pose_at`] its start and end, computed
    /// once for a turning board ([`BoardSnapshot::with_poses`]): every marble on it asks
    /// for them.
    pub poses: Option<(f32, (Vec3, Quat), (Vec3, Quat))>,
}

impl BoardSnapshot {
    /// True when the board moves or turns.
    #[inline]
    pub fn is_moving(&self) -> bool {
        self.velocity != Vec3::ZERO || self.angular_velocity != Vec3::ZERO
    }

    /// Pose at time `t` after the substep's start.
    #[inline]
    pub fn pose_at(&self, t: f32) -> (Vec3, Quat) {
        if let Some((h, start, end)) = self.poses {
            if t == 0.0 {
                return start;
            }
            if t == h {
                return end;
            }
        }
        self.pose_computed(t)
    }

    /// The snapshot with its poses at the start and end of a substep of length `h`
    /// computed once, when it turns (they cost a sine and a normalisation each).
    pub fn with_poses(mut self, h: f32) -> Self {
        if self.angular_velocity != Vec3::ZERO {
            self.poses = Some((h, self.pose_computed(0.0), self.pose_computed(h)));
        }
        self
    }

    /// [`BoardSnapshot::pose_at`], computed.
    fn pose_computed(&self, t: f32) -> (Vec3, Quat) {
        if self.angular_velocity == Vec3::ZERO {
            (self.position + self.velocity * t, self.rotation)
        } else {
            (
                self.position + self.velocity * t,
                (turn(self.angular_velocity * t) * self.rotation).normalize(),
            )
        }
    }

    /// Acceleration of the board's material point at world point `p`, time `t`: the
    /// centripetal `ω × (ω × (p − c))` of its turning (boards move at constant velocity and
    /// turn at constant rate over a step).
    #[inline(always)]
    pub fn point_accel(&self, t: f32, p: Vec3) -> Vec3 {
        if self.angular_velocity == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let w = self.angular_velocity;
        w.cross(w.cross(p - (self.position + self.velocity * t)))
    }

    /// Velocity of the board's material point at world point `p`, time `t`.
    #[inline(always)]
    pub fn point_velocity(&self, t: f32, p: Vec3) -> Vec3 {
        self.velocity
            + self
                .angular_velocity
                .cross(p - (self.position + self.velocity * t))
    }
}

/// The boards of the current substep, rebuilt by the prepare stage (capacity reused).
#[derive(Resource, Default, Debug)]
pub struct BoardCache {
    /// One snapshot per board, in a stable order (by entity).
    pub boards: Vec<BoardSnapshot>,
    /// Changes whenever the board list changes other than by motion (a board added,
    /// removed or given another shape): [`NearPieces`] lists of an older epoch are stale.
    pub epoch: u32,
    /// Each board's entity, shape, pose and pose version at the last substep.
    pub(crate) layout: Vec<(Entity, usize, Vec3, Quat, u32)>,
    /// The last pose version handed out.
    pose_versions: u32,
}

impl BoardCache {
    /// Moves to a new [`BoardCache::epoch`] if the boards' entities or shapes differ from
    /// the last call's, and to a new [`BoardSnapshot::pose_version`] each board whose pose
    /// changed (called by the prepare stage after filling `boards`).
    pub(crate) fn update_epoch(&mut self) {
        let same = self.layout.len() == self.boards.len()
            && self
                .layout
                .iter()
                .zip(&self.boards)
                .all(|(l, b)| (l.0, l.1) == (b.entity, Arc::as_ptr(&b.geometry) as usize));
        if !same {
            self.epoch = self.epoch.wrapping_add(1);
            self.layout.clear();
            self.layout.extend(self.boards.iter().map(|b| {
                (
                    b.entity,
                    Arc::as_ptr(&b.geometry) as usize,
                    b.position,
                    b.rotation,
                    0,
                )
            }));
        }
        for (l, b) in self.layout.iter_mut().zip(self.boards.iter_mut()) {
            if (l.2, l.3) != (b.position, b.rotation) {
                self.pose_versions = self.pose_versions.wrapping_add(1);
                (l.2, l.3, l.4) = (b.position, b.rotation, self.pose_versions);
            }
            b.pose_version = l.4;
        }
    }
}

/// The rotation by `|v|` about `v`'s direction (`Quat::from_scaled_axis`), its sine and
/// cosine from the `libm` crate: software, so the same bits on every platform, where the
/// standard library's `sin_cos` is the platform's own.
pub fn turn(v: Vec3) -> Quat {
    let angle = v.length();
    if angle == 0.0 {
        return Quat::IDENTITY;
    }
    let (s, c) = libm::sincosf(0.5 * angle);
    let axis = v / angle * s;
    Quat::from_xyzw(axis.x, axis.y, axis.z, c)
}
