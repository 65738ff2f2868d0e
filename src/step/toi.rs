//! Time of impact (SPEC 2.6, fig. 3.16): when an overlapping pair first
//! touched, by sampling fast paths and bisecting; which bodies roll back with
//! an impact (`impact_group`); and impacts that began before another unseen
//! (`earlier_impact`). Pure over a `Region`: every query is counted in its
//! `counters`.

use super::contact::SolvedTogether;
use super::executor::{Executor, PairKey, Segment, Since};
use super::kept::{self, Kept};
use super::region::{PairMap, Region, pose};
use crate::body::{BodyKind, BodyState, ObjectDef};
use crate::collision::manifold::NormalTurn;
use crate::collision::narrowphase::{self, CONTACT_TOLERANCE, PairResult, PairTask};
use nalgebra::Vector3;
use std::collections::{BTreeSet, HashMap};

/// Time-of-impact bisection stops once the gap is below this (metres).
pub const TOI_GAP: f64 = 0.01 * CONTACT_TOLERANCE;
/// Near the contact tolerance a point may sink only this much past what it
/// carried before its impact is placed (`allowed_depth`), so a pair that
/// closes again after every impact ratchets past the tolerance 10× slower
/// than by `TOI_GAP`.
pub const RATCHET_GAP: f64 = 0.1 * TOI_GAP;

/// How deep a contact point that was `carried` deep when its pair was last
/// solved may be before an impact is placed: `TOI_GAP` deeper, but not past
/// `CONTACT_TOLERANCE − RATCHET_GAP` unless it already was, and never less
/// than `RATCHET_GAP` deeper (each event must make progress). With
/// `TOI_GAP` for every point a pair starting a step 9.95 µm
/// deep ended it at 10.05 µm unseen, and one that closed again after each
/// impact ratcheted 0.1 µm per event (9 of 1200 sweep scenes ended up to
/// 0.14 µm past the tolerance; docs/stability.md, *Regression scenes*).
pub(crate) fn allowed_depth(carried: f64) -> f64 {
    let ceiling = CONTACT_TOLERANCE - RATCHET_GAP;
    carried + (ceiling - carried).clamp(RATCHET_GAP, TOI_GAP)
}

/// When each pair's contacts were last solved (the step's start, or an
/// impact's τ, seconds into the step) and its deepest overlap then: an
/// overlap its points already had then is carried, not new
/// (`Region::sinking`). Pairs not listed carried none.
pub(crate) type SolvedSince = PairMap<Since>;
/// One pair's time-of-impact question: pair `k` on the bodies' segments
/// `seg`, `r` its result at the end of the stretch searched, and when each
/// pair's contacts were last solved.
#[derive(Clone, Copy)]
pub(crate) struct PairAsk<'q> {
    pub k: PairKey,
    pub r: &'q PairResult,
    pub seg: &'q [Segment],
    pub since: &'q SolvedSince,
}

impl PairAsk<'_> {
    /// The stretch from where both bodies' segments start to `h`.
    fn stretch_to(&self, h: f64) -> (f64, f64) {
        let (a, b) = (self.k.0 as usize, self.k.1 as usize);
        (self.seg[a].time.max(self.seg[b].time), h)
    }
}

/// An instant at which a pair was found apart, and V-Clip's distance then.
type Apart = (f64, f64);

/// What sampling a pair's path found (`Region::first_overlap_sample`).
enum Sampled {
    /// It moves too little relative to its thickness to need samples.
    Slow,
    /// No sample (nor the end of the step) overlaps beyond what it carried.
    Apart,
    /// The first overlapping sample is `hi`; the one before, `lo`, does not
    /// overlap, and `gap` is V-Clip's distance there and a lower bound on
    /// the bodies' distance, when it was apart.
    Between {
        lo: f64,
        hi: f64,
        gap: Option<(f64, f64)>,
        /// The apart sample before `lo` and its distance, if any.
        before: Option<(f64, f64)>,
    },
}

/// A time-of-impact search that may stop part way (`Region::continue_search`).
pub(crate) enum Search {
    Found(Option<f64>),
    /// Sampling the path (boxed: most searches end at once).
    Sampling(Box<Sampling>),
    /// An overlapping instant found; the bisection before it is still to do.
    Bracket(Bracket),
}

impl Search {
    /// No impact this search can find comes before this instant: the last
    /// sample found apart, or the bracket's lower end (the bisection
    /// answers inside its bracket).
    pub(crate) fn not_before(&self) -> f64 {
        match self {
            Search::Found(tau) => tau.unwrap_or(f64::INFINITY),
            Search::Sampling(s) => s.prev,
            Search::Bracket(k) => k.lo,
        }
    }
}

/// Where a pair's sampling stands: its bounds, set up once
/// (`Region::begin_sampling`), and the samples' state.
pub(crate) struct Sampling {
    a: usize,
    b: usize,
    since: Option<Since>,
    /// The end of the interval, and where the end-of-step result proves
    /// the pair apart from (`h` where it overlaps there).
    h: f64,
    end_overlaps: bool,
    apart_from: f64,
    /// Half a thickness of relative travel, in time; the approach-speed
    /// bound; the centres' relative acceleration; swing and turn bounds.
    spacing: f64,
    speed: f64,
    accel: Vector3<f64>,
    bounds: (f64, [(f64, f64); 2]),
    /// The last sample found apart (at first the start), its distance and
    /// gap bound, the one before it, and the next sample's instant.
    prev: f64,
    prev_gap: Option<(f64, f64)>,
    before: Option<Apart>,
    t: f64,
}

/// An overlapping sample `hi` after one apart, `lo`: what `Region::bisect`
/// needs.
pub(crate) struct Bracket {
    a: usize,
    b: usize,
    since: Option<Since>,
    lo: f64,
    hi: f64,
    gap: Option<(f64, f64)>,
    before: Option<Apart>,
}

impl Region<'_> {
    /// A body an impact rolls back: a moving one that takes impulses. A
    /// driven body's path is prescribed, so it keeps its segment (rolling
    /// it back would only re-round it, differently in each group it meets).
    fn rolls_back(&self, i: usize) -> bool {
        self.moving(i) && self.bodies[i].is_dynamic()
    }

    /// Time of impact of one pair in this step, if it overlaps (or a fast
    /// pair crossed) beyond what it carried into its segment.
    pub(crate) fn time_of_impact(&mut self, q: PairAsk, h: f64) -> Option<f64> {
        self.time_of_impact_within(q, q.stretch_to(h))
    }

    /// Time of impact of one pair between `lo` and `hi` (both bodies on
    /// their segments there; `q.r` is the pair's result at `hi`), if it
    /// overlaps (or a fast pair crossed) beyond what it carried: the same
    /// search as `time_of_impact`, on a stretch of the step.
    pub(crate) fn time_of_impact_within(
        &mut self,
        q: PairAsk,
        (start, h): (f64, f64),
    ) -> Option<f64> {
        let searched = |g: &mut Self| {
            let search = g.begin_search(q, (start, h));
            match g.continue_search(search, q.seg, f64::INFINITY) {
                Search::Found(tau) => tau,
                _ => unreachable!("a search without a limit ends"),
            }
        };
        if !self.keep_answers {
            return searched(self);
        }
        // A part of a split group (`super::kept`): the search reads the
        // step's start, the two bodies and their segments, the interval,
        // when the pair was last solved, its end result and its features.
        thread_local! {
            static KEPT: std::cell::RefCell<Kept<Option<f64>>> = Default::default();
        }
        let PairAsk { k, r, seg, since } = q;
        let (a, b) = (k.0 as usize, k.1 as usize);
        let question = kept::question(&(
            self.st.t0,
            (self.ids[a], self.ids[b]),
            (&self.bodies[a], &self.bodies[b]),
            (&seg[a], &seg[b]),
            (start, h),
            since.get(&k),
            r,
            self.features.get(&k),
        ));
        kept::one_again_or_anew(&KEPT, question, || searched(self), 16)
    }

    /// A time-of-impact search of pair `q.k` over its step, taken as far as
    /// its first sample: `time_of_impact` in pieces (`continue_search`),
    /// for `impacts::PairBook`, which needs a pair's answer only once it
    /// could be the group's next event. A split group's part (`keep_answers`)
    /// searches whole, as `time_of_impact`, to keep its answers.
    pub(crate) fn begin_time_of_impact(&mut self, q: PairAsk, h: f64) -> Search {
        if self.keep_answers {
            return Search::Found(self.time_of_impact(q, h));
        }
        self.begin_search(q, q.stretch_to(h))
    }

    /// The search's set-up: the bounds its samples are spaced by, and the
    /// last stretch the end-of-step result proves apart.
    fn begin_search(&mut self, q: PairAsk, (start, h): (f64, f64)) -> Search {
        let PairAsk { k, r, seg, since } = q;
        let (a, b) = (k.0 as usize, k.1 as usize);
        let since = since.get(&k).copied();
        let end_overlaps = self.overlaps_more((a, b), r, h, seg, since);
        match self.begin_sampling(a, b, seg, (start, h), since, (r, end_overlaps)) {
            Ok(sampling) => Search::Sampling(Box::new(sampling)),
            Err(Sampled::Slow) if end_overlaps => Search::Bracket(Bracket {
                a,
                b,
                since,
                lo: start,
                hi: h,
                gap: None,
                before: None,
            }),
            Err(_) => Search::Found(None),
        }
    }

    /// Takes `search` on until its answer is known (`Search::Found`) or,
    /// where `limit` is finite, until no impact it can find comes before
    /// `limit` (`Search::not_before` past it): the search is returned where
    /// it stopped then. Its samples and bisection are the ones the whole
    /// search takes, in the same order, so the answer does not depend on
    /// where it was stopped.
    pub(crate) fn continue_search(
        &mut self,
        mut search: Search,
        seg: &[Segment],
        limit: f64,
    ) -> Search {
        loop {
            search = match search {
                Search::Found(tau) => return Search::Found(tau),
                Search::Sampling(mut s) => match self.sample_until(&mut s, seg, limit) {
                    None => return Search::Sampling(s),
                    Some(Sampled::Between {
                        lo,
                        hi,
                        gap,
                        before,
                    }) => Search::Bracket(Bracket {
                        a: s.a,
                        b: s.b,
                        since: s.since,
                        lo,
                        hi,
                        gap,
                        before,
                    }),
                    Some(_) => Search::Found(None),
                },
                Search::Bracket(k) if k.lo > limit => return Search::Bracket(k),
                Search::Bracket(k) => Search::Found(Some(self.bisect(
                    k.a,
                    k.b,
                    seg,
                    k.lo,
                    k.hi,
                    k.since,
                    (k.gap, k.before),
                ))),
            };
        }
    }

    /// An overlap that calls for a rollback: beyond the contact tolerance (or
    /// with no contact points to resolve it), with a contact point past the
    /// depth it may reach since the pair was last solved (`sinking`). An overlap
    /// carried in (rounding, or one left by a step that could not resolve
    /// it) is mended by the overlap recovery, not by rolling back to a
    /// moment that has already passed.
    fn overlaps_more(
        &self,
        (a, b): (usize, usize),
        r: &PairResult,
        t: f64,
        seg: &[Segment],
        since: Option<Since>,
    ) -> bool {
        r.needs_rollback(CONTACT_TOLERANCE)
            && (r.contacts.is_empty() || self.sinking((a, b), r, t, seg, since) > 0.0)
    }

    /// How far the pair's deepest-sinking contact point at `t` (result `r`)
    /// is past its `allowed_depth`, of what the same two body points carried
    /// at `since`, when the pair was last solved (positive calls for an
    /// impact); a point apart then carried no overlap, and none
    /// carried more than the pair's deepest point then (the old measure, so
    /// every rollback it called for is still called for). While the
    /// pair's deepest overlap then was the measure for every point, a new
    /// point of a pair already 7 µm deep landed 7 µm deep unseen: a bolt
    /// rolling on the 40-gon rim of its shaft's end, each rim corner in turn
    /// landing so and the overlap recovery lifting it out again, gained
    /// energy and wobbled for 50 s (docs/stability.md, *Regression scenes*).
    ///
    /// Each point's two body points (A's and B's, at the point at `t`) are
    /// taken back to `since` with their bodies; their gap then, along the
    /// normal turned back with the feature it belongs to (`NormalTurn`), is
    /// the gap at `t` plus n·(x_A − x_B) at `since` (to the overlap times
    /// the turn, 1e-8 m at most).
    fn sinking(
        &self,
        (a, b): (usize, usize),
        r: &PairResult,
        t: f64,
        seg: &[Segment],
        since: Option<Since>,
    ) -> f64 {
        // `r.depth` is already the deepest of the contact points.
        let Some(Since {
            time: t0,
            deepest: carried,
            ..
        }) = since
        else {
            return r.depth - allowed_depth(0.0);
        };
        if r.contacts.is_empty() {
            return r.depth - allowed_depth(carried);
        }
        let at = |i: usize, t: f64| self.integrate_segment(i, &seg[i], t - seg[i].time);
        let (sa, sb, sa0, sb0) = (at(a, t), at(b, t), at(a, t0), at(b, t0));
        let back_a = sa0.orientation * sa.orientation.inverse();
        let back_b = sb0.orientation * sb.orientation.inverse();
        r.contacts
            .iter()
            .map(|c| {
                let xa0 = sa0.position + back_a * (c.point - sa.position);
                let xb0 = sb0.position + back_b * (c.point - sb.position);
                let n0 = match c.turns {
                    NormalTurn::WithA => back_a * c.normal,
                    NormalTurn::WithB => back_b * c.normal,
                    NormalTurn::Edges(ea, eb) => {
                        let m = (back_a * ea).cross(&(back_b * eb));
                        let m = m / m.norm();
                        if m.dot(&c.normal) >= 0.0 { m } else { -m }
                    }
                };
                let gap0 = c.separation + n0.dot(&(xa0 - xb0));
                -c.separation - allowed_depth((-gap0).clamp(0.0, carried))
            })
            .fold(r.depth - allowed_depth(carried), f64::max)
    }

    /// For pairs that move by more than their thickness during the step,
    /// the sampling of the path, dense enough that one cannot pass through
    /// the other unseen (`sample_until` takes the samples), or `Slow`
    /// (`end_overlaps`: the end-of-step result, already known, overlaps).
    #[allow(clippy::too_many_arguments)]
    fn begin_sampling(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        (start, h): (f64, f64),
        since: Option<Since>,
        (end, end_overlaps): (&PairResult, bool),
    ) -> Result<Sampling, Sampled> {
        // Each body at both ends of the interval: its travel, its swing and
        // the approach-speed bound all come from these four states.
        let ends =
            |i: usize| [start, h].map(|t| self.integrate_segment(i, &seg[i], t - seg[i].time));
        let (ends_a, ends_b) = (ends(a), ends(b));
        // Relative travel of the centres, plus how far each body's corners
        // can swing about its centre: a spinning body whose centre barely
        // moves can still sweep a corner through a thin neighbour (a random
        // scene lost 10 mm that way between two samples of a pair that was
        // never sampled).
        let span = h - start;
        let swing = self.swing_rate(seg, a, &ends_a, span) + self.swing_rate(seg, b, &ends_b, span);
        let turn = [
            self.turn_bound(seg, a, &ends_a, span),
            self.turn_bound(seg, b, &ends_b, span),
        ];
        let centres =
            (ends_a[1].position - ends_a[0].position) - (ends_b[1].position - ends_b[0].position);
        let travel = centres.norm() + swing * (h - start);
        let thickness = self
            .object(a)
            .min_thickness
            .min(self.object(b).min_thickness);
        if travel <= 0.5 * thickness {
            return Err(Sampled::Slow);
        }
        // Samples every half thickness of relative travel, and further where
        // the pair is far apart: from a gap g no point can close it before
        // g / (bound on the approach speed) has passed (conservative
        // advancement), so nothing is skipped there either.
        let samples = ((travel / (0.5 * thickness)).ceil() as usize).min(10_000);
        let spacing = (h - start) / samples as f64;
        let speed = self.approach_speed_bound(seg, (a, &ends_a), (b, &ends_b), span);
        // The relative acceleration of the centres (constant on the segments).
        let accel = seg[a].force / self.object(a).mass - seg[b].force / self.object(b).mass;
        // The first sample: as far as the part spheres' gap and the plane
        // along the centres' line allow at the start, without a query (not
        // from the end-of-step result: the separating-pair skip may have
        // left it empty, and that must not change an answer).
        let first = {
            let (sa, sb) = (&ends_a[0], &ends_b[0]);
            let task = self.pair_task(a as u32, b as u32, sa, sb);
            let gap = narrowphase::part_sphere_gap(self.st.objects, &task, f64::NEG_INFINITY);
            let centres = sa.position - sb.position;
            let along = self.closing_time((a, sa), (b, sb), centres, accel, (swing, turn));
            along.max(gap.max(0.0) / speed)
        };
        // The last stretch, read backwards: a pair apart at the step's end
        // has been apart since as long before it as the same two bounds
        // give on the motion run backwards (velocities reversed; the
        // acceleration and the bounds on spin stay), so it needs no sample
        // there: each would find it apart, and the answer is the same. The
        // gap: the end-of-step result's V-Clip distance and the part spheres
        // it did not test, or where the separating-pair skip left no
        // result, every part sphere's gap.
        let apart_from = if end_overlaps {
            h
        } else {
            let (ea, eb) = (&ends_a[1], &ends_b[1]);
            let task = self.pair_task(a as u32, b as u32, ea, eb);
            let tested = end.part_pairs_tested > 0;
            let gap = if tested {
                gap_bound(self.st.objects, end, &task, None)
            } else {
                narrowphase::part_sphere_gap(self.st.objects, &task, f64::NEG_INFINITY).max(0.0)
            };
            let back = |s: &BodyState| BodyState {
                velocity: -s.velocity,
                ..*s
            };
            let axes = [
                (tested && !end.penetrating).then_some(end.closest_axis),
                Some(ea.position - eb.position),
            ];
            let along = self.longest_closing_time(
                (a, &back(ea)),
                (b, &back(eb)),
                axes,
                accel,
                (swing, turn),
            );
            h - (gap / speed).max(along)
        };
        Ok(Sampling {
            a,
            b,
            since,
            h,
            end_overlaps,
            apart_from,
            spacing,
            speed,
            accel,
            bounds: (swing, turn),
            prev: start,
            prev_gap: None,
            before: None,
            t: (start + spacing.max(first)).min(h),
        })
    }

    /// Takes the samples of `s` in order while the last one found apart
    /// (`prev`, at first the start) is not past `limit`; returns the
    /// interval before the first overlapping sample, `Apart` when none
    /// (nor the end of the step) overlaps, or `None` when it stopped at
    /// `limit` with `s` where it stopped.
    fn sample_until(&mut self, s: &mut Sampling, seg: &[Segment], limit: f64) -> Option<Sampled> {
        let (a, b, h) = (s.a, s.b, s.h);
        while s.prev <= limit {
            let t = s.t;
            if t >= s.apart_from {
                // The end-of-step result stands for a sample at h.
                return Some(if s.end_overlaps {
                    Sampled::Between {
                        lo: s.prev,
                        hi: h,
                        gap: s.prev_gap,
                        before: s.before,
                    }
                } else {
                    Sampled::Apart
                });
            }
            let (sa, sb) = self.states_at(a, b, seg, t);
            let (r, task, far) = self.sample_states(a, b, &sa, &sb);
            if self.overlaps_more((a, b), &r, t, seg, s.since) {
                return Some(Sampled::Between {
                    lo: s.prev,
                    hi: t,
                    gap: s.prev_gap,
                    before: s.before,
                });
            }
            // A lower bound on the gap: V-Clip's distance over the part pairs
            // it tested, and for the others the gap between their part
            // spheres.
            let gap = gap_bound(self.st.objects, &r, &task, far);
            // Axes to try: the closest points' line, the contact normal where
            // they touch, and the centres' line.
            let axes = [
                Some(r.closest_axis),
                r.contacts.first().map(|c| c.normal),
                Some(sa.position - sb.position),
            ];
            let along = self.longest_closing_time((a, &sa), (b, &sb), axes, s.accel, s.bounds);
            s.before = s.prev_gap.map(|(distance, _)| (s.prev, distance));
            s.prev = t;
            s.prev_gap = (!r.penetrating).then_some((r.distance, gap));
            s.t = (t + s.spacing.max(gap / s.speed).max(along)).min(h);
        }
        None
    }

    /// The longest `closing_time` over the axes given (0 with none).
    fn longest_closing_time<const N: usize>(
        &self,
        (a, sa): (usize, &BodyState),
        (b, sb): (usize, &BodyState),
        axes: [Option<Vector3<f64>>; N],
        accel: Vector3<f64>,
        bounds: (f64, [(f64, f64); 2]),
    ) -> f64 {
        axes.into_iter()
            .flatten()
            .map(|n| self.closing_time((a, sa), (b, sb), n, accel, bounds))
            .fold(0.0, f64::max)
    }

    /// How long two bodies in states `sa`, `sb` stay apart at least, by the
    /// planes normal to `axis` (`n`, out of B towards A): when
    /// s = min_A n·x − max_B n·x is positive it bounds their distance from
    /// below, and it changes at the n-velocity of the support points:
    /// the centres' relative velocity along n (linear in time: constant
    /// forces) plus n·(ω × r) for each body, r the support point's offset,
    /// |r| ≤ its reach R. That last term is bounded two ways: |ω| R at most
    /// (`swing`, bounded over the segment), and |n × ω| R now plus R |ω̇| Δ
    /// later (`turn`: R and the bound on |ω̇|, per body), which sees that a
    /// nut spinning flat on its axis does not swing across a plane normal
    /// to that axis. So s(t + Δ) ≥ s + (u − c₀)·Δ + (½ a − c₁)·Δ², once
    /// with c₀ = swing, c₁ = 0 and once with the second bound; the larger
    /// of the two first roots (+∞ when a bound never reaches zero), or 0
    /// when no such plane separates them. Conservative advancement on the
    /// gap alone crawls where bodies pass each other close by (|v| is
    /// mostly along the gap); this sees that they do not close.
    fn closing_time(
        &self,
        (a, sa): (usize, &BodyState),
        (b, sb): (usize, &BodyState),
        axis: Vector3<f64>,
        accel: Vector3<f64>,
        (swing, turn): (f64, [(f64, f64); 2]),
    ) -> f64 {
        let Some(n) = axis.try_normalize(1e-12) else {
            return 0.0;
        };
        let gap = narrowphase::separation_along(
            (self.object(a), &pose(sa)),
            (self.object(b), &pose(sb)),
            &n,
        );
        if gap.is_nan() || gap <= 0.0 {
            return 0.0;
        }
        // gap + slope·Δ + curve·Δ² = 0, first positive root (stable form).
        let first_root = |slope: f64, curve: f64| {
            let disc = slope * slope - 4.0 * curve * gap;
            if (slope >= 0.0 && curve >= 0.0) || disc < 0.0 {
                f64::INFINITY
            } else {
                2.0 * gap / (-slope + disc.sqrt())
            }
        };
        let u = (sa.velocity - sb.velocity).dot(&n);
        let across = |i: usize, s: &BodyState| -> f64 {
            let omega = match self.bodies[i].kind {
                BodyKind::Fixed => Vector3::zeros(),
                BodyKind::Driven {
                    angular_velocity, ..
                } => angular_velocity,
                BodyKind::Dynamic => self.body_at(i, *s).angular_velocity(self.object(i)),
            };
            n.cross(&omega).norm()
        };
        let c0 = across(a, sa) * turn[0].0 + across(b, sb) * turn[1].0;
        let c1 = turn[0].0 * turn[0].1 + turn[1].0 * turn[1].1;
        let curve = 0.5 * accel.dot(&n);
        first_root(u - swing, curve).max(first_root(u - c0, curve - c1))
    }

    /// Each body's reach about its centre and a bound on |ω̇| over the
    /// interval between `ends` (`closing_time`'s `turn`): from Euler's
    /// equations, ω̇ = I⁻¹(τ − ω × L) in the world frame, so
    /// |ω̇| ≤ (|τ| + |ω|·|L|) / I_min with the interval's bounds on |ω| and |L|.
    fn turn_bound(
        &self,
        seg: &[Segment],
        i: usize,
        ends: &[BodyState; 2],
        span: f64,
    ) -> (f64, f64) {
        let o = self.object(i);
        let reach = o.outer_radius();
        match self.bodies[i].kind {
            BodyKind::Dynamic => {
                let w = self.spin_bound(i, ends, &seg[i].torque, span);
                let l = ends
                    .iter()
                    .map(|s| s.angular_momentum.norm())
                    .fold(0.0, f64::max);
                let i_min = o.principal_moments.min();
                (reach, 1.01 * (seg[i].torque.norm() + w * l) / i_min)
            }
            BodyKind::Fixed | BodyKind::Driven { .. } => (reach, 0.0),
        }
    }

    /// Upper bound of body `i`'s angular speed over an interval of its
    /// segment, from the states at its ends: |L| / I_min at the larger end
    /// (|ω| itself may peak inside a segment as a body wobbles; |L|, linear
    /// in time under a constant torque, cannot), and a bound from the
    /// rotational energy T, often far tighter: |ω|² = Σ Πₖ²/Iₖ² ≤
    /// (1/I_min) Σ Πₖ²/Iₖ = 2T/I_min, and T changes at τ·ω, so over a span
    /// Δ from either end T ≤ T₀ + |τ| Δ √(2T_max/I_min), whose root in
    /// √T_max gives |ω| ≤ √(2/I_min)·(c + √(c² + 4T₀))/2 with
    /// c = |τ| Δ √(2/I_min). For a bolt tumbling end over end (T = |L|²/2I_t,
    /// I_t ≈ 5 I_min) that is about 2.2 times tighter than |L|/I_min. The
    /// splitting integrator keeps T to O((hω)⁴) along a segment, well inside
    /// the 1 % margin.
    fn spin_bound(&self, i: usize, ends: &[BodyState; 2], torque: &Vector3<f64>, span: f64) -> f64 {
        match self.bodies[i].kind {
            BodyKind::Dynamic => {
                let o = self.object(i);
                let i_min = o.principal_moments.min();
                let by_momentum = ends
                    .iter()
                    .map(|s| s.angular_momentum.norm() / i_min)
                    .fold(0.0, f64::max);
                let k = (2.0 / i_min).sqrt();
                let c = torque.norm() * span * k;
                let by_energy = ends
                    .iter()
                    .map(|s| {
                        let omega = self.body_at(i, *s).angular_velocity(o);
                        let t0 = 0.5 * omega.dot(&s.angular_momentum).max(0.0);
                        1.01 * k * 0.5 * (c + (c * c + 4.0 * t0).sqrt())
                    })
                    .fold(f64::INFINITY, f64::min);
                by_momentum.min(by_energy)
            }
            BodyKind::Fixed => 0.0,
            BodyKind::Driven {
                angular_velocity, ..
            } => angular_velocity.norm(),
        }
    }

    /// How far body `i`'s points can swing about its centre, per second,
    /// between `ends` on its segment: its spin bound times its reach.
    fn swing_rate(&self, seg: &[Segment], i: usize, ends: &[BodyState; 2], span: f64) -> f64 {
        self.spin_bound(i, ends, &seg[i].torque, span) * self.object(i).outer_radius()
    }

    /// Upper bound of the speed at which any point of `a` approaches any
    /// point of `b` over an interval, from each body's states at its two
    /// ends: relative linear speed (with a constant force, |Δv| is convex
    /// in time and peaks at an end) plus each body's swing rate.
    fn approach_speed_bound(
        &self,
        seg: &[Segment],
        (a, ends_a): (usize, &[BodyState; 2]),
        (b, ends_b): (usize, &[BodyState; 2]),
        span: f64,
    ) -> f64 {
        let linear = (0..2)
            .map(|k| (ends_a[k].velocity - ends_b[k].velocity).norm())
            .fold(0.0, f64::max);
        (linear + self.swing_rate(seg, a, ends_a, span) + self.swing_rate(seg, b, ends_b, span))
            .max(1e-12)
    }

    /// V-Clip alone at time `t`: `None` when the pair overlaps, else its gap
    /// and a lower bound on the bodies' distance (that gap, and the part
    /// spheres of the part pairs V-Clip did not test).
    fn gap_at(&mut self, a: usize, b: usize, seg: &[Segment], t: f64) -> Option<(f64, f64)> {
        let (sa, sb) = self.states_at(a, b, seg, t);
        self.counters.toi_bisection_queries += 1;
        let task = self.pair_task(a as u32, b as u32, &sa, &sb);
        let (probe, far) = narrowphase::probe_apart_and_far_gap(self.st.objects, &task);
        let (gap, _) = probe?;
        let r = PairResult {
            distance: gap,
            ..Default::default()
        };
        Some((gap, gap_bound(self.st.objects, &r, &task, Some(far))))
    }

    /// The pair at time `t`, with contact points (their depth tells an
    /// overlap carried into the segment from a new one).
    pub(crate) fn query_at(&mut self, a: usize, b: usize, seg: &[Segment], t: f64) -> PairResult {
        self.query_task_at(a, b, seg, t).0
    }

    fn query_task_at(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        t: f64,
    ) -> (PairResult, PairTask) {
        let (sa, sb) = self.states_at(a, b, seg, t);
        self.query_states(a, b, &sa, &sb)
    }

    fn states_at(&self, a: usize, b: usize, seg: &[Segment], t: f64) -> (BodyState, BodyState) {
        (
            self.integrate_segment(a, &seg[a], t - seg[a].time),
            self.integrate_segment(b, &seg[b], t - seg[b].time),
        )
    }

    /// A sample: V-Clip alone first; only a pair within the contact
    /// tolerance needs its contact points (an overlap calls for a roll-back
    /// only with them, `overlaps_more`), so only then the full query. The
    /// same answer as `query_states` for every use a sample has, at a
    /// fraction of the cost on many-faced bodies (the separating-axis
    /// search behind contact points). With the probe's answer comes the
    /// far part pairs' sphere gap (`gap_bound`'s other half, from the same
    /// pass over the part pairs); `None` where the full query answered.
    fn sample_states(
        &mut self,
        a: usize,
        b: usize,
        sa: &BodyState,
        sb: &BodyState,
    ) -> (PairResult, PairTask, Option<f64>) {
        let task = self.pair_task(a as u32, b as u32, sa, sb);
        match narrowphase::probe_apart_and_far_gap(self.st.objects, &task) {
            (Some((gap, axis)), far) if gap > CONTACT_TOLERANCE => {
                self.counters.toi_bisection_queries += 1;
                let r = PairResult {
                    distance: gap,
                    closest_axis: axis,
                    ..Default::default()
                };
                (r, task, Some(far))
            }
            _ => {
                let (r, task) = self.query_states(a, b, sa, sb);
                (r, task, None)
            }
        }
    }

    fn query_states(
        &mut self,
        a: usize,
        b: usize,
        sa: &BodyState,
        sb: &BodyState,
    ) -> (PairResult, PairTask) {
        self.counters.toi_bisection_queries += 1;
        let task = self.pair_task(a as u32, b as u32, sa, sb);
        (narrowphase::query_pair(self.st.objects, &task), task)
    }

    #[allow(clippy::too_many_arguments)]
    /// Bisection for the touching instant (SPEC 2.6, fig. 3.16): `lo` is known
    /// apart (or with no contact point deeper than when the pair was last
    /// solved, `since`), `hi` overlapping deeper. Halves until the interval is what the pair's
    /// relative speed covers in a 0.1 µm gap (`TOI_GAP`), or a separated `lo`
    /// is within that gap. At 4.4 m/s (a 1 m drop) that is 23 ns: impact times
    /// stay well within 1e-6 s over many bounces, for about
    /// log2(v·dt / 0.1 µm) ≈ 19 V-Clip queries per impact.
    ///
    /// When V-Clip finds the pair apart at `lo` by more than `TOI_GAP`, any
    /// overlap is "after the impact", and V-Clip alone decides each half: no
    /// contact points, whose separating-axis search over edge pairs costs
    /// far more than V-Clip (7× the whole bisection on the load profile's
    /// 224-face spheres). The answer is then an instant where the pair is
    /// apart by at most `TOI_GAP`. That pass makes no progress when the
    /// pair, just solved at `lo`, still closes: then, as for a pair
    /// touching or overlapping at `lo`, the depth of the contact points
    /// decides, and a point may sink to its `allowed_depth` (`TOI_GAP`
    /// deeper than it was at `since`, less near the tolerance) before the
    /// impact is placed.
    fn bisect(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        lo: f64,
        hi: f64,
        since: Option<Since>,
        (lo_gap, before): (Option<(f64, f64)>, Option<Apart>),
    ) -> f64 {
        // Forces are constant over a segment, so speeds peak at its ends.
        let speed = self
            .relative_speed_bound(a, b, seg, lo)
            .max(self.relative_speed_bound(a, b, seg, hi))
            .max(1e-9);
        let resolution = (TOI_GAP / speed).max(1e-13 * self.st.settings.dt);
        // Only for a pair clearly apart at `lo`. One touching there (V-Clip's
        // verdict flipping at rounding level as a body slides along a wall)
        // got impacts 0.15 µs apart, each at the first instant V-Clip called
        // it apart, until the step's 256 events ran out; its real sinking
        // 2.5 ms later was never reached (random sweep seed 4, scene 89).
        // (`lo_gap`: V-Clip's distance at `lo` and a lower bound on the
        // bodies' distance, when sampling found them.)
        let gap = match lo_gap {
            Some(gap) => Some(gap),
            None => self.gap_at(a, b, seg, lo),
        };
        if let Some((gap, bound)) = gap.filter(|&(gap, _)| gap > TOI_GAP) {
            let before = before.filter(|_| lo_gap.is_some());
            let tau = self.bisect_apart(a, b, seg, (lo, gap, bound), before, hi, resolution);
            if tau > lo {
                return tau;
            }
        }
        self.bisect_depth(a, b, seg, lo, hi, since, resolution)
    }

    /// Bisection on "does V-Clip find an overlap"; `lo` is apart by `gap`
    /// (V-Clip) and by at least `bound` (the bodies), `hi` overlaps. Two
    /// steps shorten the halving, neither of them trusted for the answer
    /// (that is still a queried instant apart by at most `TOI_GAP`, or the
    /// resolution): a secant step through the last two instants found apart,
    /// aimed to leave a share of the gap (`aim`; the gap is nearly linear
    /// over the short intervals left, so a few steps take it below
    /// `TOI_GAP` where halving takes 14 to 19), again after each one that
    /// halved the interval or the gap and else after one midpoint; and
    /// conservative advancement, first of all (with `lo` it gives the
    /// secant its slope) and wherever it lies beyond the midpoint: no point
    /// closes a gap g before g / (approach-speed bound) has passed, so that
    /// instant is apart. Only distances of pairs apart
    /// steer it: V-Clip's depth of an overlap is local to the features it
    /// ended on, and so to its warm start, which must not change an answer.
    #[allow(clippy::too_many_arguments)]
    fn bisect_apart(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        (mut lo, mut gap_lo, mut bound): (f64, f64, f64),
        mut before: Option<(f64, f64)>,
        mut hi: f64,
        resolution: f64,
    ) -> f64 {
        let ends = |i: usize| [lo, hi].map(|t| self.integrate_segment(i, &seg[i], t - seg[i].time));
        let speed = self.approach_speed_bound(seg, (a, &ends(a)), (b, &ends(b)), hi - lo);
        // `before`: the instant found apart before `lo`, and its gap. A
        // secant step that did not halve the interval gives its turn to
        // the midpoint.
        let mut secant_turn = true;
        // The share of the gap left at `lo` that a secant step aims to leave:
        // a gap that closes ever faster (an accelerating approach, a
        // turning corner) makes the secant land just past the touching
        // instant, so it aims short, and shorter after each overshoot.
        let mut aim = 0.1;
        while hi - lo > resolution {
            let width = hi - lo;
            let mid = lo + 0.5 * width;
            let advanced = lo + bound / speed;
            let closing = before
                .map(|(t1, g1)| (g1 - gap_lo) / (lo - t1))
                .filter(|&rate| rate > 0.0 && gap_lo.is_finite());
            let t = match closing {
                Some(rate) if secant_turn => {
                    let leave = (aim * gap_lo).max(0.5 * TOI_GAP);
                    let s = lo + (gap_lo - leave) / rate;
                    s.clamp(lo + 1e-3 * width, hi - 1e-3 * width)
                }
                _ if advanced > mid && advanced < hi => advanced,
                // No second instant apart yet: the advanced one is apart
                // (however short the step), and with `lo` it gives the
                // secant its slope.
                None if before.is_none() => advanced.clamp(lo + 1e-4 * width, mid),
                _ => mid,
            };
            let secant = secant_turn && closing.is_some();
            let gap_before = gap_lo;
            match self.gap_at(a, b, seg, t) {
                None => {
                    hi = t;
                    if secant {
                        aim = (4.0 * aim).min(0.5);
                    }
                }
                Some((gap, at_least)) => {
                    before = Some((lo, gap_lo));
                    lo = t;
                    gap_lo = gap;
                    bound = at_least;
                    if gap <= TOI_GAP {
                        break;
                    }
                    if secant {
                        aim *= 0.1;
                    }
                }
            }
            // Progress: the interval or the gap left at least halved.
            secant_turn = !secant || hi - lo <= 0.5 * width || gap_lo <= 0.5 * gap_before;
        }
        lo
    }

    /// Bisection on "has a contact point sunk past its allowed depth since
    /// `since`" (`sinking`).
    #[allow(clippy::too_many_arguments)]
    fn bisect_depth(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        mut lo: f64,
        mut hi: f64,
        since: Option<Since>,
        resolution: f64,
    ) -> f64 {
        for _ in 0..64 {
            if hi - lo <= resolution {
                break;
            }
            let mid = 0.5 * (lo + hi);
            let r = self.query_at(a, b, seg, mid);
            // `overlaps_more`, or a point sunk past its allowed depth within
            // the tolerance: together, one `sinking` call.
            if r.penetrating
                && (r.contacts.is_empty() || self.sinking((a, b), &r, mid, seg, since) > 0.0)
            {
                hi = mid;
            } else {
                lo = mid;
                if !r.penetrating && r.distance <= TOI_GAP {
                    break;
                }
            }
        }
        lo
    }

    /// The earliest impact before `tau` of a pair of the group found
    /// overlapping at τ beyond what it carried into its segment (the pair
    /// `chosen` and the pairs accepted in this step aside), by bisection
    /// from its segment's start.
    pub(crate) fn earlier_impact(
        &mut self,
        chosen: PairKey,
        tau: f64,
        (group_pairs, at_tau): (&[PairKey], &[PairResult]),
        seg: &[Segment],
        since: &SolvedSince,
        accepted: &BTreeSet<PairKey>,
    ) -> Option<(PairKey, f64)> {
        let mut best: Option<(PairKey, f64)> = None;
        for (&k, r) in group_pairs.iter().zip(at_tau) {
            let (a, b) = (k.0 as usize, k.1 as usize);
            let since = since.get(&k).copied();
            // An accepted pair made no progress at its own impact: asking
            // for it again would stall the step (the pair it was found
            // through would bring it back forever).
            if k == chosen
                || accepted.contains(&k)
                || !self.overlaps_more((a, b), r, tau, seg, since)
            {
                continue;
            }
            let start = seg[a].time.max(seg[b].time);
            if start >= tau {
                continue;
            }
            let t = self.bisect(a, b, seg, start, tau, since, (None, None));
            if t < tau && best.is_none_or(|(bk, bt)| t < bt || (t == bt && k < bk)) {
                best = Some((k, t));
            }
        }
        best
    }

    /// Upper bound of how fast any point of `a` approaches any point of `b`
    /// at time `t` (linear plus angular speed times outer radius).
    fn relative_speed_bound(&self, a: usize, b: usize, seg: &[Segment], t: f64) -> f64 {
        let bound = |i: usize| {
            let s = self.integrate_segment(i, &seg[i], t - seg[i].time);
            let o = self.object(i);
            (
                s.velocity,
                self.body_at(i, s).angular_velocity(o).norm() * o.outer_radius(),
            )
        };
        let (va, wa) = bound(a);
        let (vb, wb) = bound(b);
        (va - vb).norm() + wa + wb
    }

    /// Bodies that must roll back with an impact of `pair` at τ: the pair's
    /// moving bodies and every moving body in contact with them at τ, and so
    /// on (the contact island at τ, which the impact's LCP must hold whole).
    /// Found outwards from the pair, querying each candidate pair of a member
    /// at τ (`neighbours`: each body's candidate partners, ascending); returns the members (sorted) with their states at τ, every pair
    /// queried (each pair of a member) and its result at τ.
    ///
    /// Every other body keeps its path: none touches the group at τ, and
    /// where the group's new paths reach one later in the step, that pair's
    /// own time of impact (recomputed from τ for every pair of a member)
    /// makes it an event of its own. Events therefore stay in time order,
    /// and an impact in a pile re-solves its contact island only, not every
    /// body whose swept spheres chain to it (in a pour of 1000 that chain
    /// held about half of the bodies).
    ///
    /// A body whose path starts after τ has none there: it took an event
    /// after τ before an earlier impact (`earlier_impact`) was found at τ.
    /// It keeps its path and its pairs are not queried at τ (they are
    /// searched again from its path's start once the group's paths are
    /// new). Rolled back with the group, its state at τ was its later path
    /// run backwards: a body that had bounced off the floor 3 ms later was
    /// put 0.17 mm into it (the 1000-body pour, seed 2, at 1.07 s).
    pub(crate) fn impact_group(
        &mut self,
        exec: &mut dyn Executor,
        pair: PairKey,
        tau: f64,
        neighbours: &[Vec<u32>],
        seg: &[Segment],
        solved_together: &SolvedTogether,
    ) -> (Vec<(usize, BodyState)>, Vec<PairKey>, Vec<PairResult>) {
        let n = self.bodies.len();
        let has_state = |i: usize| seg[i].time <= tau;
        // Bodies in the group or queued for it.
        let mut claimed = vec![false; n];
        let mut group: Vec<usize> = Vec::new();
        let mut frontier: Vec<usize> = Vec::new();
        for i in [pair.0 as usize, pair.1 as usize] {
            if self.rolls_back(i) && !claimed[i] {
                claimed[i] = true;
                frontier.push(i);
            }
        }
        let mut at_tau: HashMap<usize, BodyState> = HashMap::new();
        let mut state = |world: &Region, i: usize| {
            *at_tau
                .entry(i)
                .or_insert_with(|| world.integrate_segment(i, &seg[i], tau - seg[i].time))
        };
        let mut queried: std::collections::HashSet<PairKey, rustc_hash::FxBuildHasher> =
            Default::default();
        let (mut group_pairs, mut results) = (Vec::new(), Vec::new());
        while !frontier.is_empty() {
            // Bodies whose segment forces came from one contact solve hold
            // each other's reactions: they roll back together, or one keeps
            // a force whose reaction the other no longer has (momentum
            // appears from nowhere).
            let mut k = 0;
            while k < frontier.len() {
                for &j in solved_together.partners(frontier[k]) {
                    if !claimed[j] && self.rolls_back(j) && has_state(j) {
                        claimed[j] = true;
                        frontier.push(j);
                    }
                }
                k += 1;
            }
            frontier.sort_unstable();
            group.extend(&frontier);
            // This layer's pairs, each once, in a fixed order.
            let mut layer: Vec<PairKey> = Vec::new();
            for &i in &frontier {
                for &j in &neighbours[i] {
                    let k = ((i as u32).min(j), (i as u32).max(j));
                    if has_state(j as usize) && queried.insert(k) {
                        layer.push(k);
                    }
                }
            }
            let tasks: Vec<PairTask> = layer
                .iter()
                .map(|&(a, b)| {
                    let (sa, sb) = (state(self, a as usize), state(self, b as usize));
                    self.pair_task(a, b, &sa, &sb)
                })
                .collect();
            let layer_results = self.narrowphase_tasks(exec, tasks);
            let mut next: Vec<usize> = Vec::new();
            for (&(a, b), r) in layer.iter().zip(&layer_results) {
                if r.contacts.is_empty() && !r.penetrating {
                    continue;
                }
                for j in [a as usize, b as usize] {
                    if !claimed[j] && self.rolls_back(j) {
                        claimed[j] = true;
                        next.push(j);
                    }
                }
            }
            next.sort_unstable();
            group_pairs.extend(layer);
            results.extend(layer_results);
            frontier = next;
        }
        group.sort_unstable();
        let states = group.into_iter().map(|i| (i, state(self, i))).collect();
        (states, group_pairs, results)
    }
}

/// A lower bound on the distance of a pair at the instant of its result
/// `r` (query `task`): V-Clip's distance over the part pairs it tested and
/// the part spheres' gap for the others (`far`, where the same pass that
/// probed the pair found it already; `narrowphase::far_part_gap`
/// otherwise); 0 where it overlaps.
fn gap_bound(objects: &[ObjectDef], r: &PairResult, task: &PairTask, far: Option<f64>) -> f64 {
    if r.penetrating {
        0.0
    } else {
        let far = far.unwrap_or_else(|| narrowphase::far_part_gap(objects, task));
        r.distance.min(far).max(0.0)
    }
}
