/* The token observation of the general policies (mission/tokens.py documents it), written for
 * every env of a batch by one function per entry of native.h's IOUT_TOKENS: the table of
 * writers below is generated from that list, so an entry without its writer does not compile,
 * and each writer's output is checked against its declared size. */
#include <math.h>
#include <stddef.h>

#include "../native.h"

enum { TOKEN_global, TOKEN_auv, TOKEN_node };

typedef struct {
    const Mission *m;
    int64_t e;            /* the env */
    double eta_speed_mps; /* the speed of the docking time estimate */
} TokenEnv;

/* Entries of one token of `part`, from the declaration (M = N - 1 others in an AUV token,
 * M = N AUVs in a node token). */
static int64_t token_part_size(int part, int64_t n)
{
    int64_t global_size = 0, auv_size = 0, node_size = 0;
    const int64_t global_m = 0, auv_m = n - 1, node_m = n;
    (void)global_m;
#define TOKEN_SIZE(part, name, fixed, per_auv) part##_size += (fixed) + (per_auv) * part##_m;
    IOUT_TOKENS(TOKEN_SIZE)
    return part == TOKEN_global ? global_size : part == TOKEN_auv ? auv_size : node_size;
}

static double time_remaining(const TokenEnv *t)
{
    return 1.0 - (double)t->m->s.slot[t->e] / (double)t->m->p->horizon_slots;
}

/* (cos, sin) of the direction of (dx, dy) relative to heading_rad. */
static float *bearing(double dx, double dy, double heading_rad, float *o)
{
    double rel = iout_wrap_angle(atan2(dy, dx) - heading_rad);
    *o++ = (float)cos(rel);
    *o++ = (float)sin(rel);
    return o;
}

static const double *auv_xy(const TokenEnv *t, int64_t i)
{
    return t->m->s.positions_m + 2 * (t->m->n_auvs * t->e + i);
}

static double heading_sp(const TokenEnv *t, int64_t i)
{
    return t->m->s.heading_sp[t->m->n_auvs * t->e + i];
}

/* ------------------------------------------------------------------------- global */
static float *token_global_time_remaining(const TokenEnv *t, int64_t row, int64_t k_max, float *o)
{
    *o++ = (float)time_remaining(t);
    return o;
}

static float *token_global_node_share(const TokenEnv *t, int64_t row, int64_t k_max, float *o)
{
    *o++ = (float)((double)t->m->n_nodes / (double)k_max);
    return o;
}

static float *token_global_mean_aoi(const TokenEnv *t, int64_t row, int64_t k_max, float *o)
{
    const Mission *m = t->m;
    double sum = 0.0;
    for (int64_t j = 0; j < m->n_nodes; j++)
        sum += m->net.aoi[m->n_nodes * t->e + j] / m->p->aoi_max;
    *o++ = (float)(sum / (double)m->n_nodes);
    return o;
}

/* ------------------------------------------------------------------------- AUV tokens */
static float *token_auv_position(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    const double *xy = auv_xy(t, i);
    *o++ = (float)(xy[0] / t->m->p->area_x_m);
    *o++ = (float)(xy[1] / t->m->p->area_y_m);
    return o;
}

static float *token_auv_heading_setpoint(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    *o++ = (float)cos(heading_sp(t, i));
    *o++ = (float)sin(heading_sp(t, i));
    return o;
}

static float *token_auv_speed(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    const Mission *m = t->m;
    *o++ = (float)fmin(m->s.speeds_mps[m->n_auvs * t->e + i] / m->p->v_max_mps, m->p->obs_high);
    return o;
}

static float *token_auv_speed_setpoint(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    *o++ = (float)(t->m->s.speed_sp[t->m->n_auvs * t->e + i] / t->m->p->v_max_mps);
    return o;
}

static float *token_auv_docked(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    *o++ = t->m->s.docked[t->m->n_auvs * t->e + i] ? 1.0f : 0.0f;
    return o;
}

static float *token_auv_dock_distance(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    *o++ = (float)(t->m->s.dock_dist_m[t->m->n_auvs * t->e + i] * t->m->p->inv_diag_per_m);
    return o;
}

static float *token_auv_dock_bearing(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    const double *xy = auv_xy(t, i);
    return bearing(t->m->p->dock_x_m - xy[0], t->m->p->dock_y_m - xy[1], heading_sp(t, i), o);
}

/* Time remaining less the time to fly to the dock at the estimate's speed, in [-1, 1]. */
static float *token_auv_docking_slack(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    const Params *p = t->m->p;
    double eta = t->m->s.dock_dist_m[t->m->n_auvs * t->e + i] / (t->eta_speed_mps * p->slot_s) /
                 (double)p->horizon_slots;
    *o++ = (float)fmax(-1.0, fmin(1.0, time_remaining(t) - eta));
    return o;
}

/* Distance / diagonal and bearing of every other AUV, in index order. */
static float *token_auv_other_auvs(const TokenEnv *t, int64_t i, int64_t k_max, float *o)
{
    const double *xy = auv_xy(t, i);
    for (int64_t j = 0; j < t->m->n_auvs; j++) {
        if (j == i)
            continue;
        const double *other = auv_xy(t, j);
        double dx = other[0] - xy[0], dy = other[1] - xy[1];
        *o++ = (float)(hypot(dx, dy) * t->m->p->inv_diag_per_m);
        o = bearing(dx, dy, heading_sp(t, i), o);
    }
    return o;
}

/* ------------------------------------------------------------------------- node tokens */
static float *token_node_position(const TokenEnv *t, int64_t j, int64_t k_max, float *o)
{
    const double *xy = t->m->net.nodes_m + 2 * (t->m->n_nodes * t->e + j);
    *o++ = (float)(xy[0] * (1.0 / t->m->p->area_x_m) - 0.5);
    *o++ = (float)(xy[1] * (1.0 / t->m->p->area_y_m) - 0.5);
    return o;
}

static float *token_node_aoi(const TokenEnv *t, int64_t j, int64_t k_max, float *o)
{
    *o++ = (float)(t->m->net.aoi[t->m->n_nodes * t->e + j] / t->m->p->aoi_max);
    return o;
}

static float *token_node_reset_progress(const TokenEnv *t, int64_t j, int64_t k_max, float *o)
{
    *o++ = (float)((double)t->m->net.service_count[t->m->n_nodes * t->e + j] /
                   (double)t->m->p->k_reset);
    return o;
}

static float *token_node_energy(const TokenEnv *t, int64_t j, int64_t k_max, float *o)
{
    const Params *p = t->m->p;
    *o++ = (float)iout_node_energy_level(t->m->net.energy_j[t->m->n_nodes * t->e + j],
                                         p->energy_obs_ref_j, p->obs_high);
    return o;
}

/* Per AUV: distance / diagonal, bearing, and uplink affordability
 * log10(stored energy / E_req of that link) / 3 in [-1, 2]. */
static float *token_node_auv_links(const TokenEnv *t, int64_t j, int64_t k_max, float *o)
{
    const Mission *m = t->m;
    const double *node = m->net.nodes_m + 2 * (m->n_nodes * t->e + j);
    double stored_j = fmax(m->net.energy_j[m->n_nodes * t->e + j], 1e-12);
    for (int64_t i = 0; i < m->n_auvs; i++) {
        const double *xy = auv_xy(t, i);
        double d = m->s.distance_m[(m->n_auvs * t->e + i) * m->n_nodes + j], harvest_j, need_j;
        iout_link_energy(m->link, d, iout_horizontal_m(xy, node), m->auv_depth_m[i], &harvest_j,
                         &need_j);
        *o++ = (float)(d * m->p->inv_diag_per_m);
        o = bearing(node[0] - xy[0], node[1] - xy[1], heading_sp(t, i), o);
        *o++ = (float)fmax(-1.0, fmin(2.0, log10(stored_j / need_j) / 3.0));
    }
    return o;
}

/* ------------------------------------------------------------------------- the writer */
typedef float *(*TokenWriter)(const TokenEnv *t, int64_t row, int64_t k_max, float *o);
typedef struct {
    int part;
    const char *name;
    int64_t fixed, per_auv;
    TokenWriter write;
} TokenEntry;

#define TOKEN_ENTRY(part, name, fixed, per_auv)                                                 \
    {TOKEN_##part, #part "." #name, fixed, per_auv, token_##part##_##name},
static const TokenEntry ENTRIES[] = {IOUT_TOKENS(TOKEN_ENTRY)};
enum { N_ENTRIES = sizeof ENTRIES / sizeof ENTRIES[0] };

/* One token of `part` (its entries in declared order); NULL if a writer broke its size. */
static float *write_token(const TokenEnv *t, int part, int64_t row, int64_t k_max, float *o)
{
    int64_t others = part == TOKEN_auv ? t->m->n_auvs - 1 : t->m->n_auvs;
    for (int64_t x = 0; x < N_ENTRIES; x++) {
        if (ENTRIES[x].part != part)
            continue;
        float *end = ENTRIES[x].write(t, row, k_max, o);
        if (end - o != ENTRIES[x].fixed + ENTRIES[x].per_auv * others) {
            iout_fail("iout_observe_tokens: %s wrote %lld entries, IOUT_TOKENS declares %lld",
                      ENTRIES[x].name, (long long)(end - o),
                      (long long)(ENTRIES[x].fixed + ENTRIES[x].per_auv * others));
            return NULL;
        }
        o = end;
    }
    return o;
}

int64_t iout_observe_tokens(const Mission *m, int64_t k_max, double eta_speed_mps, float *out,
                            int64_t out_size)
{
    int64_t status = iout_check_mission(m, false, false);
    if (status)
        return status;
    if (k_max < m->n_nodes || k_max > IOUT_MAX_NODES)
        return iout_fail("iout_observe_tokens: k_max %lld; accepted K = %lld to %d",
                         (long long)k_max, (long long)m->n_nodes, IOUT_MAX_NODES);
    if (!(eta_speed_mps > 0.0) || !isfinite(eta_speed_mps))
        return iout_fail("iout_observe_tokens: eta_speed_mps %g; accepted a finite speed > 0",
                         eta_speed_mps);
    int64_t node_size = token_part_size(TOKEN_node, m->n_auvs);
    int64_t per_env = token_part_size(TOKEN_global, m->n_auvs) +
                      m->n_auvs * token_part_size(TOKEN_auv, m->n_auvs) +
                      k_max * (node_size + 1);
    if (out_size != m->n_envs * per_env)
        return iout_fail("iout_observe_tokens: out holds %lld entries; accepted %lld envs x %lld",
                         (long long)out_size, (long long)m->n_envs, (long long)per_env);
    for (int64_t e = 0; e < m->n_envs; e++) {
        TokenEnv t = {m, e, eta_speed_mps};
        float *o = write_token(&t, TOKEN_global, 0, k_max, out + per_env * e);
        for (int64_t i = 0; i < m->n_auvs && o; i++)
            o = write_token(&t, TOKEN_auv, i, k_max, o);
        for (int64_t j = 0; j < m->n_nodes && o; j++)
            o = write_token(&t, TOKEN_node, j, k_max, o);
        if (!o)
            return IOUT_EINVAL;
        for (int64_t x = m->n_nodes * node_size; x < k_max * node_size; x++)
            *o++ = 0.0f; /* padded nodes */
        for (int64_t j = 0; j < k_max; j++)
            *o++ = j < m->n_nodes ? 1.0f : 0.0f; /* the node mask */
    }
    return IOUT_OK;
}
