//! The contact impulses kept from one substep to the next for warm starting, by key.
//!
//! A substep's rows come in nearly the order of the substep before: the pair rows in the
//! order of the candidate pairs, which stand until the broad phase's bounds are rebuilt,
//! the board rows in the marbles' order. So the impulses are kept as the last substep's
//! rows left them, each with its row's place in that order (a pair's place among the
//! candidate pairs, a board row's marble), and each row finds its own by walking them
//! alongside, in step with its place: a compare of neighbouring memory instead of a hash
//! probe at a random place (in a 10,000-marble pile, 35,000 pair rows a substep). Only the
//! rows that walk misses (new contacts, rows of the strays, every row once the candidates
//! are found afresh) are looked up by hashing, among the kept entries the walk did not
//! match. A place's kept entries are searched at most [`SAME_PLACE`] deep, so that rows
//! given one place (which no caller does) cost a hash lookup each, not a walk of them all.
//!
//! What a key finds is what a map from key to the last substep's impulse gives: a row is
//! matched only to a kept entry of its own key, every kept entry the walk does not match
//! is in the hashed rest, and a substep's rows hold each key once.

use super::KeyMap;

/// A warm-start key: a pair's two marbles' entity bits (smaller first), or a marble's
/// entity bits and a board piece's id with its bits flipped (never a pair's).
pub(crate) type Key = (u64, u64);

/// How many kept entries of one place the walk compares with a row's key: a pair's place
/// holds one, a board row's marble a few.
const SAME_PLACE: usize = 16;

/// The impulses of both kinds of rows, pairs and board contacts, and those put back for
/// marbles that woke.
#[derive(Default, Debug)]
pub(crate) struct Warm {
    pub(super) pairs: WarmImpulses,
    pub(super) boards: WarmImpulses,
    /// Impulses put back for marbles that woke ([`Warm::restore`]): they win over a kept
    /// entry of the same key, and are forgotten with the kept entries when the next solve
    /// keeps its own ([`Warm::keep`]). Not sized in advance: it grows to the largest group
    /// woken at once and keeps that room, as the sleeping marbles' store does.
    restored: KeyMap,
    /// The substep length the kept impulses were applied over, s (0: none kept yet).
    h: f32,
}

impl Warm {
    /// Room for `pairs` pair rows and `touches` board rows, so that keeping and finding
    /// their impulses allocates nothing.
    pub(crate) fn reserve(&mut self, pairs: usize, touches: usize) {
        self.pairs.reserve(pairs);
        self.boards.reserve(touches);
    }

    /// Forgets every impulse (no marble touches another).
    pub(crate) fn clear(&mut self) {
        self.pairs.clear();
        self.boards.clear();
        self.restored.clear();
    }

    /// Calls `found(k, λ)` for each of `keys`, the pair rows of this substep in order
    /// (`places`: each row's place among the candidate pairs, ascending), that the last
    /// substep kept (or that was put back), with its impulse; rows it did not keep get no
    /// call.
    pub(crate) fn find_pairs(
        &mut self,
        keys: &[Key],
        places: impl Iterator<Item = u32>,
        found: impl FnMut(usize, f32),
    ) {
        self.pairs.find(keys, places, &self.restored, found);
    }

    /// [`Warm::find_pairs`] for the board rows (`places`: each row's marble, ascending).
    pub(crate) fn find_boards(
        &mut self,
        keys: &[Key],
        places: impl Iterator<Item = u32>,
        found: impl FnMut(usize, f32),
    ) {
        self.boards.find(keys, places, &self.restored, found);
    }

    /// Keeps this substep's impulses for the next, each kind in its rows' order (key,
    /// place, impulse): the rows with a positive impulse. What was put back is forgotten.
    pub(crate) fn keep(
        &mut self,
        pairs: impl Iterator<Item = (Key, u32, f32)>,
        boards: impl Iterator<Item = (Key, u32, f32)>,
        h: f32,
    ) {
        self.h = h;
        self.restored.clear();
        self.pairs.keep(pairs);
        self.boards.keep(boards);
    }

    /// The factor that turns the kept impulses into those of a substep of length `h`: an
    /// impulse carried over a substep is a force times its length, so a step whose
    /// substeps changed length (`dt` or `substeps` changed between steps) warm starts
    /// from the same forces. Exactly 1 while the length holds (no bit changes).
    pub(crate) fn scale(&self, h: f32) -> f32 {
        scale(self.h, h)
    }

    /// The substep length the kept impulses were applied over, s (0: none kept yet).
    pub(crate) fn h(&self) -> f32 {
        self.h
    }

    /// Every impulse a lookup would find, with its key.
    pub(crate) fn iter(&self) -> impl Iterator<Item = (Key, f32)> + '_ {
        let kept = self.pairs.iter().chain(self.boards.iter());
        let restored = self.restored.iter().map(|(&key, &lambda)| (key, lambda));
        kept.filter(|(key, _)| !self.restored.contains_key(key))
            .chain(restored)
    }

    /// Puts back an impulse kept while its marbles slept.
    pub(crate) fn restore(&mut self, key: Key, lambda: f32) {
        self.restored.insert(key, lambda);
    }
}

/// The factor from impulses applied over substeps of length `from` to those of length
/// `to` (forces held): exactly 1 where the lengths are equal or `from` is 0 (unknown).
pub(crate) fn scale(from: f32, to: f32) -> f32 {
    if from == to || from == 0.0 {
        1.0
    } else {
        to / from
    }
}

/// Contact impulses kept while their marbles sleep, by key, and the substep length they
/// were applied over ([`crate::sleep`]).
#[derive(Default, Debug)]
pub(crate) struct StowedImpulses {
    pub(super) impulses: KeyMap,
    pub(super) h: f32,
}

impl StowedImpulses {
    /// True when none is kept.
    pub(crate) fn is_empty(&self) -> bool {
        self.impulses.is_empty()
    }
}

/// One kind of rows' impulses (pairs, or board contacts) as the last substep's solve left
/// them, in its rows' order, with the scratch of the next lookup.
#[derive(Default, Debug)]
pub(crate) struct WarmImpulses {
    keys: Vec<Key>,
    places: Vec<u32>,
    lambdas: Vec<f32>,
    /// Lookup scratch: which kept entries the walk matched, the rows it missed, and the
    /// kept entries it did not match, by key.
    matched: Vec<bool>,
    misses: Vec<u32>,
    rest: KeyMap,
    /// Test only: impulses found by the walk and by hashing.
    #[cfg(test)]
    pub(super) walked: usize,
    #[cfg(test)]
    pub(super) hashed: usize,
}

impl WarmImpulses {
    fn reserve(&mut self, rows: usize) {
        self.keys.reserve(rows);
        self.places.reserve(rows);
        self.lambdas.reserve(rows);
        self.matched.reserve(rows);
        self.misses.reserve(rows);
        self.rest.reserve(rows);
    }

    fn clear(&mut self) {
        self.keys.clear();
        self.places.clear();
        self.lambdas.clear();
    }

    /// [`Warm::find_pairs`] for this kind, `restored` looked up first.
    fn find(
        &mut self,
        keys: &[Key],
        places: impl Iterator<Item = u32>,
        restored: &KeyMap,
        mut found: impl FnMut(usize, f32),
    ) {
        let n = self.keys.len();
        self.matched.clear();
        self.matched.resize(n, false);
        self.misses.clear();
        // The kept entries before `cursor` are at earlier places than the rows to come.
        let mut cursor = 0;
        for (k, (key, place)) in keys.iter().zip(places).enumerate() {
            if !restored.is_empty()
                && let Some(&lambda) = restored.get(key)
            {
                found(k, lambda);
                continue;
            }
            while cursor < n && self.places[cursor] < place {
                cursor += 1;
            }
            let same_place = self.places[cursor..].iter().take_while(|&&p| p == place);
            match (same_place.take(SAME_PLACE))
                .zip(&self.keys[cursor..])
                .position(|(_, kept)| kept == key)
            {
                Some(at) => {
                    let at = cursor + at;
                    self.matched[at] = true;
                    found(k, self.lambdas[at]);
                    #[cfg(test)]
                    {
                        self.walked += 1;
                    }
                }
                None => self.misses.push(k as u32),
            }
        }
        if self.misses.is_empty() {
            return;
        }
        self.rest.clear();
        let kept = self.keys.iter().zip(&self.lambdas).zip(&self.matched);
        for ((&key, &lambda), _) in kept.filter(|(_, matched)| !**matched) {
            self.rest.insert(key, lambda);
        }
        if self.rest.is_empty() {
            return;
        }
        for &k in &self.misses {
            if let Some(&lambda) = self.rest.get(&keys[k as usize]) {
                found(k as usize, lambda);
                #[cfg(test)]
                {
                    self.hashed += 1;
                }
            }
        }
    }

    fn keep(&mut self, rows: impl Iterator<Item = (Key, u32, f32)>) {
        self.clear();
        for (key, place, lambda) in rows {
            if lambda > 0.0 {
                self.keys.push(key);
                self.places.push(place);
                self.lambdas.push(lambda);
            }
        }
    }

    fn iter(&self) -> impl Iterator<Item = (Key, f32)> + '_ {
        self.keys.iter().copied().zip(self.lambdas.iter().copied())
    }
}
