"""The reward: one small function per term in `rewards.c`, each scaled by its signed weight.

The terms are declared once, in `native.h` (IOUT_REWARD_TERMS), which orders both the C
function table and `REWARD_TERMS`; the list below documents them, in that order (checked at
import). The compiled slot (`mission.rules`) evaluates every term of a slot into the
mission's term array; the reward is their sum in that order, and
every term is logged (`info["reward_terms"]`, TensorBoard). Weights live in `RewardWeights`
with their signs, thresholds in `RewardConfig`. The terms:

- docking_progress: reduction of the summed dock distances over the slot.
- aoi: the mean AoI over the nodes (the paper's objective).
- fairness: 1 - Jain's index of the deliveries, once more than a few were made.
- boundary: AUVs whose straight move would have left the area.
- stall: active AUVs that moved less than `stall_distance_m`.
- energy_margin: mean over active AUVs of tanh((stored - E_req) / E_req) at the node each
  collects from.
- infeasible_uplink: active AUVs whose node cannot pay E_req.
- collision: the paper's Gaussian margin penalty below d_th, over pairs not both docked.
- docking: each first entry, and every AUV docked for the first time in the episode.
- deadline: shaping by the deadline slack (how much farther from the dock than reachable at
  v_ref in the time left), whose negative is the potential.
- undocked_at_end: AUVs not docked when the episode ends.
- aoi_after_mission: ending early does not stop the data from ageing: the AoI term of the
  slots left until T_max, with no more service, is booked when the episode ends.
"""

import re

from iout_mj import native

REWARD_TERMS: tuple[str, ...] = native.REWARD_TERMS
"""The terms in the order of the term array, as `native.h` declares them (IOUT_REWARD_TERMS)."""
native.require_names(
    "the reward terms (documented in mission/rewards.py)",
    REWARD_TERMS,
    tuple(re.findall(r"^- (\w+):", __doc__ or "", flags=re.M)),
)
