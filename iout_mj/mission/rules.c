/* The paper's rules of a slot, compiled: one implementation for every backend (see
 * mission/rules.py, which states them and calls these functions). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../native.h"

static const char *const ACTION_FIELDS[4] = {"heading", "speed", "aet_node", "uplink_node"};

/* The first action index of `actions` ((B, N, 4)) outside its range, as an error. */
static int64_t check_actions(const Mission *m, const int64_t *actions, const char *where)
{
    int64_t high[4] = {m->heading_levels, m->speed_levels, m->n_nodes, m->n_nodes};
    for (int64_t j = 0; j < m->n_envs * m->n_auvs * 4; j++) {
        if (actions[j] >= 0 && actions[j] < high[j % 4])
            continue;
        int64_t e = j / (4 * m->n_auvs), auv = (j / 4) % m->n_auvs;
        char env[32] = "";
        if (m->n_envs > 1)
            snprintf(env, sizeof env, "env %lld, ", (long long)e);
        iout_fail("%s%sAUV %lld: %s index %lld is out of range; accepted 0 to %lld", where, env,
                  (long long)auv, ACTION_FIELDS[j % 4], (long long)actions[j],
                  (long long)(high[j % 4] - 1));
        return IOUT_EACTION;
    }
    return IOUT_OK;
}

#define OBS_SIZE(name, per_auv, per_node, per_pair, fixed)                                      \
    +(per_auv) * n + (per_node) * k + (per_pair) * n * k + (fixed)
static int64_t observation_size(int64_t n, int64_t k) { return 0 IOUT_OBSERVATION(OBS_SIZE); }

/* What every entry point checks of a Mission: its sizes against each other and against C's
 * bounds, every env's slot in [0, T_max], and the action indices it is about to read (the
 * slot's inputs, `actions`, or the state's last actions, `state_actions`). */
int64_t iout_check_mission(const Mission *m, bool actions, bool state_actions)
{
    if (m->n_envs < 1 || m->n_auvs < 1 || m->n_auvs > IOUT_MAX_AUVS || m->n_nodes < 1 ||
        m->n_nodes > IOUT_MAX_NODES || m->horizon_slots < 1 ||
        m->horizon_slots != m->p->horizon_slots || m->heading_levels < 1 ||
        m->speed_levels < 1 || m->n_path < 0 ||
        m->n_obs != observation_size(m->n_auvs, m->n_nodes))
        return iout_fail("mission sizes are inconsistent (envs %lld, AUVs %lld, nodes %lld, "
                         "T_max %lld/%lld, levels %lld/%lld, path %lld, observation %lld): "
                         "the mission's view was changed outside mission.core",
                         (long long)m->n_envs, (long long)m->n_auvs, (long long)m->n_nodes,
                         (long long)m->horizon_slots, (long long)m->p->horizon_slots,
                         (long long)m->heading_levels, (long long)m->speed_levels,
                         (long long)m->n_path, (long long)m->n_obs);
    for (int64_t e = 0; e < m->n_envs; e++)
        if (m->s.slot[e] < 0 || m->s.slot[e] > m->horizon_slots)
            return iout_fail("env %lld is at slot %lld; accepted 0 to T_max = %lld (the "
                             "mission state was changed outside the rules)",
                             (long long)e, (long long)m->s.slot[e], (long long)m->horizon_slots);
    if (actions && check_actions(m, m->actions, ""))
        return IOUT_EACTION;
    if (state_actions && check_actions(m, m->s.action, "the state's last action: "))
        return IOUT_EACTION;
    return IOUT_OK;
}

/* An angle wrapped to (-pi, pi], the one convention of every measured heading. */
double iout_wrap_angle(double angle_rad)
{
    return M_PI - fmod(fmod(M_PI - angle_rad, 2 * M_PI) + 2 * M_PI, 2 * M_PI);
}

bool iout_in_area(const Params *p, double x, double y)
{
    return 0.0 <= x && x <= p->area_x_m && 0.0 <= y && y <= p->area_y_m;
}

/* Setpoints of env e from its (N, 4) action indices: theta_sp += dtheta (unwrapped),
 * v_sp = clip(v_sp + dv, 0, V_max); docked AUVs stop. Also the straight-line end of the
 * slot's move and whether it leaves the area (a boundary attempt). */
void iout_begin_env(const Mission *m, int64_t e)
{
    const Params *p = m->p;
    const State *s = &m->s;
    for (int64_t i = e * m->n_auvs; i < (e + 1) * m->n_auvs; i++) {
        const int64_t *a = m->actions + 4 * i;
        bool moving = !s->docked[i];
        memcpy(s->action + 4 * i, a, 4 * sizeof(int64_t));
        if (moving) {
            s->heading_sp[i] += m->dtheta_rad[a[0]];
            s->speed_sp[i] = fmin(fmax(s->speed_sp[i] + m->dv_mps[a[1]], 0.0), p->v_max_mps);
        } else {
            s->speed_sp[i] = 0.0;
        }
        double step_m = s->speed_sp[i] * p->slot_s;
        double x = s->positions_m[2 * i] + step_m * cos(s->heading_sp[i]);
        double y = s->positions_m[2 * i + 1] + step_m * sin(s->heading_sp[i]);
        s->straight_end_m[2 * i] = x;
        s->straight_end_m[2 * i + 1] = y;
        s->boundary_attempt[i] = moving && !iout_in_area(p, x, y);
    }
}

int64_t iout_begin_slot(const Mission *m)
{
    int64_t status = iout_check_mission(m, true, false);
    if (status)
        return status;
    for (int64_t e = 0; e < m->n_envs; e++)
        iout_begin_env(m, e);
    return IOUT_OK;
}

/* ------------------------------------------------------------------------- the slot */
/* How much farther from the dock an undocked AUV is than it can fly at v_ref in the time
 * left (0 when on schedule or docked); its negative is the shaping potential. */
static double deadline_slack_m(const Params *p, double dock_dist_m, bool docked, int64_t slot)
{
    if (docked)
        return 0.0;
    double reach_m = p->deadline_speed_mps * (double)(p->horizon_slots - slot) * p->slot_s;
    return fmax(0.0, dock_dist_m - reach_m);
}

/* Sum over the slots left until T_max of the mean AoI if no node is served again:
 * sum_{j=1..L} min(a + j, A_max) per node, in closed form. */
double iout_unserved_aoi(const Params *p, int64_t slot, const double *aoi, int64_t k)
{
    double left = (double)(p->horizon_slots - slot > 0 ? p->horizon_slots - slot : 0);
    double total = 0.0;
    for (int64_t j = 0; j < k; j++) {
        double rising = fmin(fmax(floor(p->aoi_max - aoi[j]), 0.0), left); /* before the cap */
        total += rising * aoi[j] + rising * (rising + 1) / 2 + (left - rising) * p->aoi_max;
    }
    return total / (double)k;
}

int64_t iout_unserved_aoi_sum(const Params *p, int64_t slot, const double *aoi, int64_t k,
                              double *out)
{
    if (k < 1)
        return iout_fail("iout_unserved_aoi_sum: %lld nodes; accepted at least 1", (long long)k);
    *out = iout_unserved_aoi(p, slot, aoi, k);
    return IOUT_OK;
}

/* Closest approach and collisions over a slot's path (S points of (N, 2), `stride` doubles
 * apart); pairs of AUVs both parked at the dock are left out. */
static void book_separation(const Mission *m, int64_t e, const double *path_m, int64_t stride,
                            int64_t n_path, const bool *was_docked)
{
    const State *s = &m->s;
    for (int64_t i = 0; i < m->n_auvs; i++)
        for (int64_t j = i + 1; j < m->n_auvs; j++) {
            if (was_docked[i] && was_docked[j])
                continue;
            double gap = INFINITY;
            for (int64_t t = 0; t < n_path; t++) {
                const double *x = path_m + t * stride;
                gap = fmin(gap, hypot(x[2 * i] - x[2 * j], x[2 * i + 1] - x[2 * j + 1]));
            }
            s->min_separation_m[e] = fmin(s->min_separation_m[e], gap);
            s->collisions[e] += gap < m->p->collision_distance_m;
        }
}

/* Log env e's state after `slot` slots (kept up to T_max). */
static void record(const Mission *m, int64_t e, int64_t slot)
{
    int64_t n = m->n_auvs, t = m->horizon_slots;
    if (slot < 0 || slot > t)
        return;
    const Log *log = &m->log;
    int64_t row = e * (t + 1) + slot;
    memcpy(log->positions_m + 2 * n * row, m->s.positions_m + 2 * n * e, 2 * n * sizeof(double));
    memcpy(log->headings_rad + n * row, m->s.headings_rad + n * e, n * sizeof(double));
    memcpy(log->speeds_mps + n * row, m->s.speeds_mps + n * e, n * sizeof(double));
    log->mean_aoi[row] = m->net.mean_aoi[e];
    log->jain[row] = m->net.jain[e];
}

/* Book env e's slot after the vehicles moved: energy (the dock powers docked AUVs' hotel
 * load), the network (distances at the end of the slot), docking, termination, reward terms,
 * statistics and the log. Per-AUV inputs are env e's (N, ...) rows. */
void iout_end_env(const Mission *m, int64_t e, const double *positions_m,
                  const double *headings_rad, const double *speeds_mps,
                  const double *propulsion_energy_j, const double *yaw_energy_j,
                  const double *path_m, int64_t path_stride, int64_t n_path)
{
    const Params *p = m->p;
    const State *s = &m->s;
    int64_t n = m->n_auvs, k = m->n_nodes, a0 = e * n;
    bool was_docked[n], active[n], uplink_ok[n], delivered[k];
    double moved_m[n], req_j[n], stored_j[n], harvested_j[k], dock_dist_m[n], slack_m[n];
    for (int64_t i = 0; i < n; i++) {
        int64_t a = a0 + i;
        was_docked[i] = s->docked[a];
        active[i] = !was_docked[i];
        moved_m[i] = hypot(positions_m[2 * i] - s->positions_m[2 * a],
                           positions_m[2 * i + 1] - s->positions_m[2 * a + 1]);
        s->positions_m[2 * a] = positions_m[2 * i];
        s->positions_m[2 * a + 1] = positions_m[2 * i + 1];
        s->headings_rad[a] = headings_rad[i];
        s->speeds_mps[a] = speeds_mps[i];
        double hotel_j = was_docked[i] ? 0.0 : p->hotel_j;
        s->propulsion_energy_j[a] += propulsion_energy_j[i] + hotel_j;
        s->yaw_energy_j[a] += yaw_energy_j[i];
        s->battery_j[a] -= propulsion_energy_j[i] + yaw_energy_j[i] + hotel_j;
    }
    LinkOutcomes out = {m->channel_draws + a0 * IOUT_CHANNEL_DRAWS(n), m->link_sinr_db + a0,
                        m->link_per + a0, m->link_packets_sent + a0,
                        m->link_packets_received + a0};
    iout_serve_env(&m->net, e, n, k, m->link, m->channel, p->k_reset, p->aoi_max, positions_m,
                   m->auv_depth_m, m->node_depth_m, s->action + 4 * a0 + 2, s->action + 4 * a0 + 3, 4, active,
                   s->distance_m + a0 * k, uplink_ok, req_j, stored_j, harvested_j, delivered,
                   &out);

    bool all_docked = true, battery_empty = false;
    for (int64_t i = 0; i < n; i++) {
        int64_t a = a0 + i;
        dock_dist_m[i] = hypot(positions_m[2 * i] - p->dock_x_m, positions_m[2 * i + 1] - p->dock_y_m);
        s->docked[a] = s->docked[a] || (dock_dist_m[i] <= p->dock_radius_m &&
                                        speeds_mps[i] <= p->dock_max_speed_mps);
        all_docked = all_docked && s->docked[a];
        battery_empty = battery_empty || s->battery_j[a] <= 0.0;
    }
    bool all_docked_first = all_docked && !s->all_docked_paid[e];
    s->all_docked_paid[e] = s->all_docked_paid[e] || all_docked;
    int64_t slot = ++s->slot[e];
    for (int64_t i = 0; i < n; i++)
        slack_m[i] = deadline_slack_m(p, dock_dist_m[i], s->docked[a0 + i], slot);
    s->terminated[e] = all_docked || battery_empty;
    s->truncated[e] = slot >= p->horizon_slots && !s->terminated[e];
    bool ending = s->terminated[e] || s->truncated[e];
    s->aoi_after_mission[e] = ending ? iout_unserved_aoi(p, slot, m->net.aoi + e * k, k) : 0.0;
    double mean_aoi = m->net.mean_aoi[e], jain = m->net.jain[e];
    int64_t deliveries = 0;
    for (int64_t j = 0; j < k; j++)
        deliveries += m->net.deliveries[e * k + j];
    SlotContext c = {
        .n_auvs = n,
        .active = active,
        .moved_m = moved_m,
        .boundary_attempt = s->boundary_attempt + a0,
        .positions_m = positions_m,
        .docked = s->docked + a0,
        .all_docked_first = all_docked_first,
        .dock_dist_before_m = s->dock_dist_m + a0,
        .dock_dist_m = dock_dist_m,
        .slack_before_m = s->deadline_slack_m + a0,
        .slack_m = slack_m,
        .mean_aoi = mean_aoi,
        .jain = jain,
        .deliveries = deliveries,
        .uplink_stored_j = stored_j,
        .uplink_req_j = req_j,
        .ending = ending,
        .aoi_after_mission = s->aoi_after_mission[e],
    };
    s->reward[e] = iout_slot_terms(p, &c, m->terms + e * N_REWARD_TERMS);
    memcpy(s->deadline_slack_m + a0, slack_m, n * sizeof(double));
    memcpy(s->dock_dist_m + a0, dock_dist_m, n * sizeof(double));
    s->sum_mean_aoi[e] += mean_aoi;
    s->sum_objective[e] += mean_aoi + p->fairness_lambda * (1.0 - jain);
    book_separation(m, e, path_m, path_stride, n_path, was_docked);
    record(m, e, slot);
    if (slot <= m->horizon_slots) {
        int64_t row = (e * m->horizon_slots + slot - 1) * n;
        for (int64_t i = 0; i < n; i++) {
            m->log.aet_nodes[row + i] = s->action[4 * (a0 + i) + 2];
            m->log.uplink_nodes[row + i] = s->action[4 * (a0 + i) + 3];
            m->log.uplink_ok[row + i] = uplink_ok[i];
        }
    }
}

int64_t iout_end_slot(const Mission *m)
{
    int64_t status = iout_check_mission(m, false, true);
    if (status)
        return status;
    int64_t n = m->n_auvs;
    for (int64_t e = 0; e < m->n_envs; e++)
        iout_end_env(m, e, m->end_positions_m + 2 * n * e, m->end_headings_rad + n * e,
                     m->end_speeds_mps + n * e, m->propulsion_energy_j + n * e,
                     m->yaw_energy_j + n * e, m->path_m + 2 * n * e, 2 * n * m->n_envs,
                     m->n_path);
    return IOUT_OK;
}

/* What follows from a restart's draws (positions, nodes): distances, dock distances, deadline
 * slack and the log's first entry, in the envs where `restarted`. */
int64_t iout_start(const Mission *m, const bool *restarted)
{
    int64_t status = iout_check_mission(m, false, false);
    if (status)
        return status;
    const Params *p = m->p;
    const State *s = &m->s;
    int64_t n = m->n_auvs, k = m->n_nodes;
    for (int64_t e = 0; e < m->n_envs; e++) {
        if (!restarted[e])
            continue;
        iout_distances(s->positions_m + 2 * n * e, m->auv_depth_m, n, m->net.nodes_m + 2 * k * e,
                       m->node_depth_m, k, s->distance_m + n * k * e);
        for (int64_t a = e * n; a < (e + 1) * n; a++) {
            double x = s->positions_m[2 * a], y = s->positions_m[2 * a + 1];
            s->dock_dist_m[a] = hypot(x - p->dock_x_m, y - p->dock_y_m);
            s->deadline_slack_m[a] = deadline_slack_m(p, s->dock_dist_m[a], s->docked[a], s->slot[e]);
        }
        record(m, e, s->slot[e]);
    }
    return IOUT_OK;
}

/* ------------------------------------------------------------------------- observation */
/* The observed node energy, log10(1 + e / ref) / 5, clipped to the observation's top. */
double iout_node_energy_level(double energy_j, double ref_j, double high)
{
    return fmin(log10(1.0 + energy_j / ref_j) / 5.0, high);
}

int64_t iout_node_energy_levels(const double *energy_j, int64_t count, double ref_j,
                                double high, double *out)
{
    if (count < 0)
        return iout_fail("iout_node_energy_levels: count %lld < 0", (long long)count);
    for (int64_t j = 0; j < count; j++)
        out[j] = iout_node_energy_level(energy_j[j], ref_j, high);
    return IOUT_OK;
}

/* The observation groups, one function each, named and ordered by IOUT_OBSERVATION
 * (native.h): each writes env e's entries from `o` on and returns the end. */
typedef double *(*ObservationGroup)(const Mission *m, int64_t e, double *o);

static double *obs_auv_position(const Mission *m, int64_t e, double *o)
{
    const double *xy = m->s.positions_m + 2 * m->n_auvs * e;
    for (int64_t i = 0; i < m->n_auvs; i++) {
        *o++ = xy[2 * i] / m->p->area_x_m;
        *o++ = xy[2 * i + 1] / m->p->area_y_m;
    }
    return o;
}

static double *obs_auv_heading(const Mission *m, int64_t e, double *o)
{
    const double *heading = m->s.headings_rad + m->n_auvs * e;
    for (int64_t i = 0; i < m->n_auvs; i++) {
        *o++ = cos(heading[i]);
        *o++ = sin(heading[i]);
    }
    return o;
}

/* Speed over ground / V_max, clipped to the observation's top (a current can push an AUV
 * faster than V_max). */
static double *obs_auv_speed(const Mission *m, int64_t e, double *o)
{
    for (int64_t i = 0; i < m->n_auvs; i++)
        *o++ = fmin(m->s.speeds_mps[m->n_auvs * e + i] / m->p->v_max_mps, m->p->obs_high);
    return o;
}

static double *obs_docked(const Mission *m, int64_t e, double *o)
{
    for (int64_t i = 0; i < m->n_auvs; i++)
        *o++ = m->s.docked[m->n_auvs * e + i];
    return o;
}

static double *obs_aoi(const Mission *m, int64_t e, double *o)
{
    for (int64_t j = 0; j < m->n_nodes; j++)
        *o++ = m->net.aoi[m->n_nodes * e + j] / m->p->aoi_max;
    return o;
}

static double *obs_node_energy(const Mission *m, int64_t e, double *o)
{
    for (int64_t j = 0; j < m->n_nodes; j++)
        *o++ = iout_node_energy_level(m->net.energy_j[m->n_nodes * e + j], m->p->energy_obs_ref_j,
                                      m->p->obs_high);
    return o;
}

static double *obs_distance(const Mission *m, int64_t e, double *o)
{
    int64_t nk = m->n_auvs * m->n_nodes;
    for (int64_t ij = 0; ij < nk; ij++)
        *o++ = m->s.distance_m[nk * e + ij] * m->p->inv_diag_per_m;
    return o;
}

static double *obs_dock_distance(const Mission *m, int64_t e, double *o)
{
    for (int64_t i = 0; i < m->n_auvs; i++)
        *o++ = m->s.dock_dist_m[m->n_auvs * e + i] * m->p->inv_diag_per_m;
    return o;
}

static double *obs_time_remaining(const Mission *m, int64_t e, double *o)
{
    *o++ = 1.0 - (double)m->s.slot[e] / (double)m->p->horizon_slots;
    return o;
}

#define OBS_FUNCTION(name, per_auv, per_node, per_pair, fixed) obs_##name,
static const ObservationGroup OBSERVATION_GROUPS[] = {IOUT_OBSERVATION(OBS_FUNCTION)};

/* The flat observation of every env, (B, n_obs), group by group. */
int64_t iout_observe(const Mission *m)
{
    int64_t status = iout_check_mission(m, false, false);
    if (status)
        return status;
    int64_t groups = sizeof OBSERVATION_GROUPS / sizeof OBSERVATION_GROUPS[0];
    for (int64_t e = 0; e < m->n_envs; e++) {
        double *o = m->obs + m->n_obs * e;
        for (int64_t g = 0; g < groups; g++)
            o = OBSERVATION_GROUPS[g](m, e, o);
    }
    return IOUT_OK;
}
