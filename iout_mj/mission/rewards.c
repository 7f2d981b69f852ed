/* The reward terms, one small function each, named and ordered by IOUT_REWARD_TERMS
 * (native.h); each is scaled by its signed weight (config.RewardWeights). */
#include <math.h>

#include "../native.h"

static int64_t count(const bool *x, int64_t n)
{
    int64_t total = 0;
    for (int64_t i = 0; i < n; i++)
        total += x[i];
    return total;
}

static double docking_progress(const Params *p, const SlotContext *c)
{
    double total = 0.0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        total += c->dock_dist_before_m[i] - c->dock_dist_m[i];
    return p->w_docking_progress * total;
}

static double aoi(const Params *p, const SlotContext *c) { return p->w_aoi * c->mean_aoi; }

/* Unfairness 1 - J, once more than a few updates were delivered in all. */
static double fairness(const Params *p, const SlotContext *c)
{
    return c->deliveries > p->fairness_min_deliveries ? p->w_fairness * (1.0 - c->jain) : 0.0;
}

static double boundary(const Params *p, const SlotContext *c)
{
    return p->w_boundary * (double)count(c->boundary_attempt, c->n_auvs);
}

/* Active AUVs that moved less than the stall distance in the slot. */
static double stall(const Params *p, const SlotContext *c)
{
    int64_t stalled = 0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        stalled += c->active[i] && c->moved_m[i] < p->stall_distance_m;
    return p->w_stall * (double)stalled;
}

/* Mean over AUVs of tanh((stored - E_req) / E_req) at the node each active AUV collects from. */
static double energy_margin(const Params *p, const SlotContext *c)
{
    double total = 0.0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        if (c->active[i])
            total += tanh((c->uplink_stored_j[i] - c->uplink_req_j[i]) /
                          (c->uplink_req_j[i] + p->margin_epsilon_j));
    return p->w_energy_margin / (double)c->n_auvs * total;
}

static double infeasible_uplink(const Params *p, const SlotContext *c)
{
    int64_t infeasible = 0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        infeasible += c->active[i] && c->uplink_stored_j[i] < c->uplink_req_j[i];
    return p->w_infeasible_uplink * (double)infeasible;
}

/* The paper's Gaussian margin penalty below d_th, summed over pairs not both docked. */
static double collision(const Params *p, const SlotContext *c)
{
    double total = 0.0;
    const double *x = c->positions_m;
    for (int64_t i = 0; i < c->n_auvs; i++)
        for (int64_t j = i + 1; j < c->n_auvs; j++) {
            if (c->docked[i] && c->docked[j])
                continue;
            double gap = fmax(0.0, p->safety_distance_m -
                                       hypot(x[2 * i] - x[2 * j], x[2 * i + 1] - x[2 * j + 1]));
            total += 1.0 - exp(-(gap * gap) / (2 * p->collision_sigma_m * p->collision_sigma_m));
        }
    return p->w_collision * total;
}

static double docking(const Params *p, const SlotContext *c)
{
    int64_t newly = 0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        newly += c->docked[i] && c->active[i];
    return p->w_dock_first_entry * (double)newly + p->w_dock_all * c->all_docked_first;
}

/* Shaping by the deadline slack, whose negative is the potential. */
static double deadline(const Params *p, const SlotContext *c)
{
    double total = 0.0;
    for (int64_t i = 0; i < c->n_auvs; i++)
        total += c->slack_before_m[i] - c->slack_m[i];
    return p->w_deadline * total;
}

static double undocked_at_end(const Params *p, const SlotContext *c)
{
    if (!c->ending)
        return 0.0;
    return p->w_undocked_at_end * (double)(c->n_auvs - count(c->docked, c->n_auvs));
}

/* Ending early does not stop the nodes' data from ageing: the AoI term of the slots left
 * until T_max, with no more service, is booked when the episode ends. */
static double aoi_after_mission(const Params *p, const SlotContext *c)
{
    return p->w_aoi * c->aoi_after_mission;
}

typedef double (*Term)(const Params *, const SlotContext *);

#define TERM_FUNCTION(name) name,
static const Term TERMS[N_REWARD_TERMS] = {IOUT_REWARD_TERMS(TERM_FUNCTION)};

double iout_slot_terms(const Params *p, const SlotContext *c, double *out)
{
    double total = 0.0;
    for (int t = 0; t < N_REWARD_TERMS; t++) {
        out[t] = TERMS[t](p, c);
        total += out[t];
    }
    return total;
}
