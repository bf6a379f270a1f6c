"""A training loss on the stance foot: how fast a model's predicted motion moves a foot that the real motion
keeps planted (bench/notes/2026-11-25-history.md).

Maximum likelihood alone left both flows sliding their stance feet, and their most likely motion (every latent
zero: the mode path) carrying the stance foot along with the body, where real motion keeps it still. This loss
takes the frame pairs where the real foot is down (the rule of metrics.foot_contacts: ankle and toe within
CONTACT_HEIGHT of their lowest point in the window, in both frames) and there the world speed of the same foot in
the model's prediction, in metres per second. The prediction is the mode, or a sample from latents drawn at a
temperature (the config's `stance_temperature`), which makes the loss see the sampling noise too. FL predicts the
whole window and MG each frame from the real frames before it, so the loss costs one inverse pass of the flow,
all frames at once. The shipped fl_cpu and mg_cpu use it on samples at temperature 1.

Units: features are in metres in the root frame of each frame, and control frame t is the root's step from
frame t-1 (forward, sideways, yaw; features.to_features). A foot's displacement from frame t-1 to frame t,
seen from frame t-1's root, is rotate_y(p_t, yaw step) + (sideways, 0, forward) - p_{t-1}.
"""

import torch

from ..metrics.objective import CONTACT_FALLBACK, CONTACT_HEIGHT
from ..motion import skeleton

_FEET = torch.tensor(skeleton.FEET).reshape(-1, 2)  # (ankle, toe) per foot


def _feet(x):
    """Foot joints of poses [B, T, 63] (metres): [B, T, n_feet, 2, 3]."""
    return x.reshape(*x.shape[:-1], skeleton.N_JOINTS, 3)[..., _FEET.to(x.device), :]


def foot_world_steps(prev, cur, ctrl):
    """Horizontal displacement (x, z) of each foot joint from poses prev [B, n, 63] to cur [B, n, 63] under the
    control of cur's frames ctrl [B, n, 3], all in metres and radians: [B, n, n_feet, 2, 2]."""
    p0, p1 = _feet(prev), _feet(cur)  # features.rotate_y's rotation, written in torch so that gradients pass
    yaw = ctrl[..., 2][..., None, None]
    cos, sin = torch.cos(yaw), torch.sin(yaw)
    x = cos * p1[..., 0] + sin * p1[..., 2] + ctrl[..., 1][..., None, None]
    z = -sin * p1[..., 0] + cos * p1[..., 2] + ctrl[..., 0][..., None, None]
    return torch.stack([x - p0[..., 0], z - p0[..., 2]], dim=-1)


def contacts(window, first, contact_height=CONTACT_HEIGHT, fallback=CONTACT_FALLBACK):
    """Contact of each foot in the frame pairs (t-1, t), t = first..T-1, of poses window [B, T, 63] (metres):
    bool [B, T - first, n_feet], by metrics.foot_contacts' rule, its fallback included (a foot of a jittery
    sample that is never still counts as down in its lowest `fallback` share of pairs, so the loss sees it).
    Not differentiable: the loss weighs the feet that are down, not where they are."""
    height = _feet(window)[..., 1]  # [B, T, n_feet, 2]
    rel = (height - height.amin(dim=1, keepdim=True)).amax(dim=-1)  # [B, T, n_feet], the higher joint
    score = torch.maximum(rel[:, first:], rel[:, first - 1 : -1])
    floor = torch.quantile(score, fallback, dim=1, keepdim=True).clamp_min(contact_height)
    return score <= floor


def stance_speed(prev, cur, ctrl, contact, fps):
    """Mean horizontal speed (m/s) of the feet of cur over the frame pairs where `contact` [B, n, n_feet] holds,
    per batch element [B] (0 where a window has no contact)."""
    speed = foot_world_steps(prev, cur, ctrl).norm(dim=-1).mean(dim=-1) * fps  # [B, n, n_feet]
    mask = contact.to(speed.dtype)
    return (speed * mask).sum(dim=(1, 2)) / mask.sum(dim=(1, 2)).clamp_min(1.0)


def stance_height(cur, real, contact):
    """Mean height gap (m) between the feet of cur [B, n, 63] and of the real frames real [B, n, 63] over the frame
    pairs where `contact` [B, n, n_feet] holds, per batch element [B] (0 where a window has no contact). A planted
    foot neither rises nor bobs: MG's stance feet, horizontally still under stance_speed, bob from frame to frame
    several times as much as the mocap's (bench/RESULTS.md "model-realism")."""
    gap = (_feet(cur)[..., 1] - _feet(real)[..., 1]).abs().mean(dim=-1)  # [B, n, n_feet], ankle and toe
    mask = contact.to(gap.dtype)
    return (gap * mask).sum(dim=(1, 2)) / mask.sum(dim=(1, 2)).clamp_min(1.0)


def posture_offset(pred, real, categories=None):
    """Mean squared distance (m^2) over joints between the batch's mean root-frame pose in the prediction and in
    the real windows [B, n, 63], one scalar. A first-moment match of the posture: it leaves each window free to
    differ from its real one (FL has no history to follow), and holds the sampled posture where the data's is.
    With `categories` [B] (integer codes of the windows' locomotion categories) the mean is matched within each
    category and the squared distances averaged over the batch's windows: a model may hold the batch's mean pose
    while leaning back on side-steps and forward on backward walks (FL did, by 6-14 cm)."""
    gap = (pred - real).mean(dim=1)  # [B, 63]: each window's mean pose gap
    if categories is None:
        categories = torch.zeros(len(gap), dtype=torch.long, device=gap.device)
    member = torch.nn.functional.one_hot(categories.long()).to(gap.dtype)  # [B, G]
    counts = member.sum(dim=0)
    offset = (member.T @ gap) / counts.clamp_min(1.0)[:, None]  # [G, 63]
    per_category = offset.reshape(len(offset), skeleton.N_JOINTS, 3).pow(2).sum(dim=-1).mean(dim=-1)
    return (per_category * counts).sum() / counts.sum()


def posture_spread(pred, real):
    """Mean squared difference (m^2) over joints between how far the windows' mean poses spread over the batch
    in the prediction and in the real windows [B, n, 63] (their standard deviation per coordinate), one scalar.
    The second moment beside posture_offset's first: on samples, the stance loss left every FL window with the
    same posture (its windows' mean poses spread a third as far as NAT's), the average walker whatever the
    latent; this holds the spread of postures over windows where the data's is."""
    if len(pred) < 2:
        return pred.new_zeros(())
    gap = pred.mean(dim=1).std(dim=0) - real.mean(dim=1).std(dim=0)
    return gap.reshape(skeleton.N_JOINTS, 3).pow(2).sum(dim=-1).mean()


def stance_loss(net, x, c, fps, keep=None, history=None, z=None, posture=0.0, spread=0.0, height=0.0, categories=None):
    """Stance-foot speed (m/s) of `net`'s prediction of training windows x [B, T, 63], c [B, T, 3] (standardised)
    from latents z [B, T, 63] (None: zeros, the most likely motion; MG reads frames tau..T-1 of it), over the real
    windows' contact frames, per batch element [B]. Both frames of each pair are predictions: FL predicts the
    whole window; MG predicts frames tau..T-1, each from the real frames before it (with its NLL's history dropout
    mask and history noise), so an offset that the model makes in every frame cancels, as it does in a sampled
    clip, and the loss sees the foot's motion alone.

    With `posture` > 0 the loss adds that weight times posture_offset of the same prediction: the plain loss, on
    samples, bent FL's whole posture to still its feet (hands 9 cm low, feet 7 cm forward), which likelihood alone
    did not (bench/RESULTS.md "fl-posture"); with `categories` [B] it is matched within each category. With
    `spread` > 0 it adds that weight times posture_spread, which keeps the samples' postures as varied over windows
    as the data's. With `height` > 0 it adds that weight times stance_height: the planted feet at the real foot's
    height (m), which the horizontal speed alone leaves free."""
    real, ctrl = net.unstandardize_x(x), c * net.c_std + net.c_mean
    if net.kind == "mg":
        pred = net.predict_frames(x, c, None if z is None else z[:, net.tau :], keep, history)
        pred, first = net.unstandardize_x(pred), net.tau + 1
    else:
        pred, first = net.unstandardize_x(net.inverse((torch.zeros_like(x) if z is None else z).flatten(1), c)[0]), 1
    down = contacts(real, first)
    loss = stance_speed(pred[:, :-1], pred[:, 1:], ctrl[:, first:], down, fps)
    if height:
        loss = loss + height * stance_height(pred[:, 1:], real[:, first:], down)
    if posture:
        loss = loss + posture * posture_offset(pred, real[:, first - 1 :], categories)
    if spread:
        loss = loss + spread * posture_spread(pred, real[:, first - 1 :])
    return loss
