/* The sensor network's slot rules and the link budget, compiled (world/network.py states the
 * rules; this file is their one implementation). */
#include <math.h>

#include "../native.h"

#define INITIAL_AOI 1.0 /* world.network.INITIAL_AOI: an update resets the age to one slot */

void iout_link_energy(const Link *link, double distance_m, double *harvest_j, double *uplink_j)
{
    double d = fmax(distance_m, link->min_distance_m);
    double spread = pow(d, link->spreading);
    *harvest_j = link->harvest_j * exp(link->wet_per_m * d) / spread;
    *uplink_j = link->uplink_j * exp(link->data_per_m * d) * spread;
}

int64_t iout_link_energies(const Link *link, const double *distance_m, int64_t count,
                           double *harvest_j, double *uplink_j)
{
    if (count < 0)
        return iout_fail("iout_link_energies: count %lld < 0", (long long)count);
    for (int64_t i = 0; i < count; i++)
        iout_link_energy(link, distance_m[i], &harvest_j[i], &uplink_j[i]);
    return IOUT_OK;
}

double iout_jain(const int64_t *counts, int64_t k)
{
    double total = 0.0, sq = 0.0;
    for (int64_t j = 0; j < k; j++) {
        total += (double)counts[j];
        sq += (double)counts[j] * (double)counts[j];
    }
    return total * total / ((double)k * sq + (sq == 0.0)); /* 0 if nothing was delivered */
}

static double mean(const double *x, int64_t k)
{
    double total = 0.0;
    for (int64_t j = 0; j < k; j++)
        total += x[j];
    return total / (double)k;
}

int64_t iout_summarise(const Network *net, int64_t n_envs, int64_t k)
{
    if (n_envs < 1 || k < 1)
        return iout_fail("iout_summarise: %lld environments of %lld nodes; accepted at least 1 "
                         "of each", (long long)n_envs, (long long)k);
    for (int64_t e = 0; e < n_envs; e++) {
        net->mean_aoi[e] = mean(net->aoi + e * k, k);
        net->jain[e] = iout_jain(net->deliveries + e * k, k);
    }
    return IOUT_OK;
}

void iout_distances(const double *auv_xy, int64_t n, const double *nodes_m, int64_t k,
                    double *distance_m)
{
    for (int64_t i = 0; i < n; i++)
        for (int64_t j = 0; j < k; j++)
            distance_m[i * k + j] =
                hypot(auv_xy[2 * i] - nodes_m[2 * j], auv_xy[2 * i + 1] - nodes_m[2 * j + 1]);
}

/* One slot of env e's nodes; the node indices must lie in [0, k) (checked by the callers). */
void iout_serve_env(const Network *net, int64_t e, int64_t n, int64_t k, const Link *link,
                    int64_t k_reset, double aoi_max, const double *auv_xy, const int64_t *wet,
                    const int64_t *data, int64_t node_stride, const bool *active,
                    double *distance_m, bool *uplink_ok, double *uplink_req_j,
                    double *uplink_stored_j, double *harvested_j, bool *delivered)
{
    const double *nodes = net->nodes_m + e * k * 2;
    double *energy = net->energy_j + e * k, *aoi = net->aoi + e * k;
    int64_t *count = net->service_count + e * k, *deliveries = net->deliveries + e * k;
    double request_j[k]; /* the cheapest E_req of the active AUVs naming each node */
    for (int64_t j = 0; j < k; j++) {
        request_j[j] = INFINITY; /* no active AUV named the node */
        harvested_j[j] = 0.0;
    }
    iout_distances(auv_xy, n, nodes, k, distance_m);
    for (int64_t i = 0; i < n; i++) {
        int64_t up = data[i * node_stride], charge = wet[i * node_stride];
        for (int64_t j = 0; j < k; j++) {
            if (j != up && j != charge)
                continue;
            double harvest, need;
            iout_link_energy(link, distance_m[i * k + j], &harvest, &need);
            if (j == up) {
                uplink_req_j[i] = need;
                uplink_stored_j[i] = energy[j];
                if (active[i] && need < request_j[j])
                    request_j[j] = need;
            }
            if (j == charge && active[i])
                harvested_j[j] += harvest;
        }
    }
    for (int64_t j = 0; j < k; j++) {
        delivered[j] = energy[j] >= request_j[j]; /* energy stored at the start of the slot */
        energy[j] += harvested_j[j] - (delivered[j] ? request_j[j] : 0.0);
        deliveries[j] += delivered[j];
        count[j] += delivered[j];
        if (count[j] >= k_reset) {
            aoi[j] = INITIAL_AOI;
            count[j] = 0;
        } else {
            aoi[j] = fmin(aoi[j] + 1.0, aoi_max);
        }
    }
    for (int64_t i = 0; i < n; i++)
        uplink_ok[i] = active[i] && delivered[data[i * node_stride]];
    net->mean_aoi[e] = mean(aoi, k);
    net->jain[e] = iout_jain(deliveries, k);
}

/* The network rules of one slot on their own (for their tests), checked. */
int64_t iout_serve(const Network *net, int64_t e, int64_t n_envs, int64_t n, int64_t k,
                   const Link *link, int64_t k_reset, double aoi_max, const double *auv_xy,
                   const int64_t *wet, const int64_t *data, int64_t node_stride,
                   const bool *active, double *distance_m, bool *uplink_ok,
                   double *uplink_req_j, double *uplink_stored_j, double *harvested_j,
                   bool *delivered)
{
    if (e < 0 || e >= n_envs || n < 1 || n > IOUT_MAX_AUVS || k < 1 || k > IOUT_MAX_NODES ||
        node_stride < 1)
        return iout_fail("iout_serve: env %lld of %lld, %lld AUVs, %lld nodes, stride %lld; "
                         "accepted an env in [0, envs), 1 to %d AUVs, 1 to %d nodes and a stride >= 1",
                         (long long)e, (long long)n_envs, (long long)n, (long long)k,
                         (long long)node_stride, IOUT_MAX_AUVS, IOUT_MAX_NODES);
    for (int64_t i = 0; i < n; i++) {
        int64_t w = wet[i * node_stride], d = data[i * node_stride];
        if (w < 0 || w >= k || d < 0 || d >= k)
            return iout_fail("iout_serve: AUV %lld names nodes %lld and %lld; accepted 0 to %lld",
                             (long long)i, (long long)w, (long long)d, (long long)(k - 1));
    }
    iout_serve_env(net, e, n, k, link, k_reset, aoi_max, auv_xy, wet, data, node_stride, active,
                   distance_m, uplink_ok, uplink_req_j, uplink_stored_j, harvested_j, delivered);
    return IOUT_OK;
}
