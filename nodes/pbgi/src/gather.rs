//! The gather loop every microbuffer gather shares (`PbgiGather`, `WaveletGather`): receivers in
//! Z order, each traversing the tree into its own buffer, the image and the counts summed in
//! receiver order.

use super::traversal::{GatherBuffer, GatherCounts, NodeRadiance, Traversal};
use crate::types::Receivers;
use glam::Vec3;
use relume_base::math::frame::Frame;
use relume_base::math::morton::morton2;
use relume_base::types::Image;
use relume_core::{NodeError, RunCtx};

/// Receivers gathered with one microbuffer (a unit of parallel work and of progress).
const RECEIVERS_PER_TASK: usize = 16;

/// The gather over traversal `t` (whatever its nodes send) into copies of `blank` (uniform
/// or adaptive): one buffer per receiver, convolved with the receiver's BRDF. Receivers are
/// taken in Z order over the image (`z_order`), so a task's receivers are a small square and
/// see the tree's nodes from nearly the same place (what memos of node values reuse); each
/// receiver's result is its own, so the order changes no byte.
pub fn gather_with<R: NodeRadiance, B: GatherBuffer>(
    t: &Traversal<R>,
    r: &Receivers,
    blank: B,
    cx: &RunCtx,
) -> Result<(Image, GatherCounts), NodeError> {
    let order = z_order(r);
    let tasks = cx.par_map(r.len().div_ceil(RECEIVERS_PER_TASK), |task| {
        let (mut mb, mut stack) = (blank.clone(), Vec::new());
        let first = task * RECEIVERS_PER_TASK;
        order[first..(first + RECEIVERS_PER_TASK).min(r.len())]
            .iter()
            .map(|&i| {
                let i = i as usize;
                let mut counts = GatherCounts::default();
                if !mb.shades(&r.material[i]) {
                    return (Vec3::ZERO, counts);
                }
                let frame = Frame::from_normal(r.normal[i]);
                let wo = frame.to_local(r.wo[i]);
                mb.begin(&r.material[i], wo);
                mb.gather(t, &r.material[i], r.position[i], &frame, &mut stack, &mut counts);
                (mb.end(&r.material[i], wo), counts)
            })
            .collect::<Vec<_>>()
    })?;
    let mut img = r.blank_image();
    let mut total = GatherCounts::default();
    for (&i, (l, c)) in order.iter().zip(tasks.into_iter().flatten()) {
        r.add_to(&mut img, i as usize, l);
        total = total + c;
    }
    r.fill_in(&mut img);
    Ok((img, total))
}

/// The receivers' indices sorted by the Morton code of their pixel (`math::morton`; ties
/// keep the receivers' order).
pub fn z_order(r: &Receivers) -> Vec<u32> {
    let w = r.width.max(1);
    let key = |i: u32| {
        let p = r.pixel[i as usize] as usize;
        morton2(p % w, p / w)
    };
    let mut order: Vec<u32> = (0..r.len() as u32).collect();
    order.sort_by_key(|&i| key(i));
    order
}
