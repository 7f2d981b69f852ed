/* The sensor network's slot rules and the link budget, compiled (world/network.py states the
 * rules; this file is their one implementation). */
#include <math.h>
#include <stddef.h>

#include "../native.h"

#define INITIAL_AOI 1.0 /* world.network.INITIAL_AOI: an update resets the age to one slot */

/* The link energies of an AUV and a node: the harvest of one charging period and the uplink's
 * E_req. With the link's TL table (tl_ranges > 0), harvest_j 10^(-TL_wet / 10) and uplink_j
 * 10^(TL_data / 10) at the horizontal range and the AUV's depth; else spreading and absorption
 * over the (slant) distance, the paper's formula. */
void iout_link_energy(const Link *link, double distance_m, double horizontal_m,
                      double auv_depth_m, double *harvest_j, double *uplink_j)
{
    if (link->tl_ranges > 0) {
        double wet_db = iout_tl_at(link->tl_range_m, link->tl_ranges, link->tl_depth_m,
                                   link->tl_depths, link->tl_wet_db, horizontal_m, auv_depth_m);
        double data_db = iout_tl_at(link->tl_range_m, link->tl_ranges, link->tl_depth_m,
                                    link->tl_depths, link->tl_data_db, horizontal_m, auv_depth_m);
        *harvest_j = link->harvest_j * pow(10.0, -0.1 * wet_db);
        *uplink_j = link->uplink_j * pow(10.0, 0.1 * data_db);
        return;
    }
    double d = fmax(distance_m, link->min_distance_m);
    double spread = pow(d, link->spreading);
    *harvest_j = link->harvest_j * exp(link->wet_per_m * d) / spread;
    *uplink_j = link->uplink_j * exp(link->data_per_m * d) * spread;
}

/* The horizontal range between an AUV and a node, (x, y) each. */
double iout_horizontal_m(const double *auv_xy, const double *node_xy)
{
    return hypot(auv_xy[0] - node_xy[0], auv_xy[1] - node_xy[1]);
}

/* The slant range of a horizontal range and a depth difference, as iout_distances takes it. */
static double slant_m(double horizontal_m, double dz_m)
{
    return dz_m == 0.0 ? horizontal_m : hypot(horizontal_m, dz_m);
}

/* The link energies at distances (no depths: the paper's plane), for a link without a table. */
int64_t iout_link_energies(const Link *link, const double *distance_m, int64_t count,
                           double *harvest_j, double *uplink_j)
{
    if (count < 0)
        return iout_fail("iout_link_energies: count %lld < 0", (long long)count);
    if (link->tl_ranges > 0)
        return iout_fail("iout_link_energies: the link has a transmission-loss table, over "
                         "horizontal range and AUV depth; accepted through "
                         "iout_link_pair_energies");
    for (int64_t i = 0; i < count; i++)
        iout_link_energy(link, distance_m[i], distance_m[i], 0.0, &harvest_j[i], &uplink_j[i]);
    return IOUT_OK;
}

/* The link energies of pairs: horizontal ranges, AUV depths and node depths (count each). */
int64_t iout_link_pair_energies(const Link *link, const double *horizontal_m,
                                const double *auv_depth_m, const double *node_depth_m,
                                int64_t count, double *harvest_j, double *uplink_j)
{
    if (count < 0)
        return iout_fail("iout_link_pair_energies: count %lld < 0", (long long)count);
    for (int64_t i = 0; i < count; i++) {
        double d = slant_m(horizontal_m[i], node_depth_m[i] - auv_depth_m[i]);
        iout_link_energy(link, d, horizontal_m[i], auv_depth_m[i], &harvest_j[i], &uplink_j[i]);
    }
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

/* AUV-node ranges: slant, with the depth difference node_depth_m[j] - auv_depth_m[i] (NULL
 * depths: 0), and horizontal where that difference is 0 (the paper's). */
void iout_distances(const double *auv_xy, const double *auv_depth_m, int64_t n,
                    const double *nodes_m, const double *node_depth_m, int64_t k,
                    double *distance_m)
{
    for (int64_t i = 0; i < n; i++)
        for (int64_t j = 0; j < k; j++) {
            double d = iout_horizontal_m(auv_xy + 2 * i, nodes_m + 2 * j);
            double dz = (node_depth_m ? node_depth_m[j] : 0.0) - (auv_depth_m ? auv_depth_m[i] : 0.0);
            distance_m[i * k + j] = slant_m(d, dz);
        }
}

/* Absorption of sound in sea water in dB/km at f_khz, Francois & Garrison (1982), "Sound
 * absorption based on ocean measurements. Part II: Boric acid contribution and equation for
 * total absorption", J. Acoust. Soc. Am. 72(6):1879-1890, eqs. 2-4: relaxations of boric acid
 * (A1 P1 f1 f^2 / (f1^2 + f^2)) and magnesium sulphate (A2 P2 f2 f^2 / (f2^2 + f^2)) plus pure
 * water's viscosity (A3 P3 f^2), at temperature t (deg C), salinity s (ppt), depth z (m) and
 * pH, with their sound speed c = 1412 + 3.21 t + 1.19 s + 0.0167 z and theta = 273 + t. */
static double francois_garrison(double f, double t, double s, double z, double ph)
{
    double c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * z, theta = 273.0 + t, f2 = f * f;
    double a1 = 8.86 / c * pow(10.0, 0.78 * ph - 5.0);
    double f1 = 2.8 * sqrt(s / 35.0) * pow(10.0, 4.0 - 1245.0 / theta);
    double a2 = 21.44 * s / c * (1.0 + 0.025 * t);
    double p2 = 1.0 - 1.37e-4 * z + 6.2e-9 * z * z;
    double fm = 8.17 * pow(10.0, 8.0 - 1990.0 / theta) / (1.0 + 0.0018 * (s - 35.0));
    double a3 = t <= 20.0 ? 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t * t - 1.5e-8 * t * t * t
                          : 3.964e-4 - 1.146e-5 * t + 1.45e-7 * t * t - 6.5e-10 * t * t * t;
    double p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z * z;
    return a1 * f1 * f2 / (f1 * f1 + f2) + a2 * p2 * fm * f2 / (fm * fm + f2) + a3 * p3 * f2;
}

int64_t iout_francois_garrison(const double *f_khz, int64_t count, double temperature_degc,
                               double salinity_ppt, double depth_m, double ph,
                               double *alpha_db_per_km)
{
    if (count < 0)
        return iout_fail("iout_francois_garrison: count %lld < 0", (long long)count);
    for (int64_t i = 0; i < count; i++)
        alpha_db_per_km[i] = francois_garrison(f_khz[i], temperature_degc, salinity_ppt,
                                               depth_m, ph);
    return IOUT_OK;
}

/* ------------------------------------------------------------------ site-specific TL */
/* The cell of `x` on the strictly increasing axis[0..count) and its weight on the upper node:
 * x clamped to [axis[0], axis[count - 1]] (a one-node axis is constant). */
static int64_t axis_cell(const double *axis, int64_t count, double x, double *weight)
{
    *weight = 0.0;
    if (count < 2 || x <= axis[0])
        return 0;
    if (x >= axis[count - 1]) {
        *weight = 1.0;
        return count - 2;
    }
    int64_t lo = 0, hi = count - 1; /* axis[lo] <= x < axis[hi] */
    while (hi - lo > 1) {
        int64_t mid = (lo + hi) / 2;
        if (axis[mid] <= x)
            lo = mid;
        else
            hi = mid;
    }
    *weight = (x - axis[lo]) / (axis[lo + 1] - axis[lo]);
    return lo;
}

/* Bilinear interpolation of tl_db (depth-major: tl_db[d * n_range + r]) at (range, depth),
 * clamped to the table's edges (world.tl_table states the table). */
double iout_tl_at(const double *range_m, int64_t n_range, const double *depth_m, int64_t n_depth,
                  const double *tl_db, double range, double depth)
{
    double wr, wd;
    int64_t r = axis_cell(range_m, n_range, range, &wr);
    int64_t d = axis_cell(depth_m, n_depth, depth, &wd);
    int64_t r1 = n_range > 1 ? r + 1 : r, d1 = n_depth > 1 ? d + 1 : d;
    double top = (1.0 - wr) * tl_db[d * n_range + r] + wr * tl_db[d * n_range + r1];
    double bottom = (1.0 - wr) * tl_db[d1 * n_range + r] + wr * tl_db[d1 * n_range + r1];
    return (1.0 - wd) * top + wd * bottom;
}

int64_t iout_tl_interpolate(const double *range_m, int64_t n_range, const double *depth_m,
                            int64_t n_depth, const double *tl_db, const double *at_range_m,
                            const double *at_depth_m, int64_t count, double *out_db)
{
    if (n_range < 1 || n_depth < 1 || count < 0)
        return iout_fail("iout_tl_interpolate: a %lld x %lld table at %lld points; accepted at "
                         "least one range and one depth", (long long)n_depth,
                         (long long)n_range, (long long)count);
    for (int64_t i = 0; i < count; i++)
        out_db[i] = iout_tl_at(range_m, n_range, depth_m, n_depth, tl_db, at_range_m[i],
                               at_depth_m[i]);
    return IOUT_OK;
}

/* ------------------------------------------------------------------ the channel's rules */
/* Bit error rate in AWGN at Eb/N0 (linear), Proakis, Digital Communications (5th ed.):
 * coherent BPSK 0.5 erfc(sqrt(Eb/N0)) (eq. 4.3-13); non-coherent binary FSK
 * 0.5 exp(-Eb/(2 N0)) (eq. 4.5-45). */
static double bit_error_rate(int64_t modulation, double ebn0)
{
    return modulation == IOUT_BFSK ? 0.5 * exp(-0.5 * ebn0) : 0.5 * erfc(sqrt(ebn0));
}

/* PER = 1 - (1 - BER)^bits, every bit of a packet needed (no coding), at a linear SINR. */
static double packet_error_rate(const Channel *ch, double sinr)
{
    double ber = bit_error_rate(ch->modulation, sinr * ch->ebn0_per_snr);
    return -expm1(ch->packet_bits * log1p(-ber));
}

int64_t iout_packet_error_rates(const Channel *ch, const double *sinr, int64_t count, double *per)
{
    if (count < 0)
        return iout_fail("iout_packet_error_rates: count %lld < 0", (long long)count);
    for (int64_t i = 0; i < count; i++)
        per[i] = packet_error_rate(ch, sinr[i]);
    return IOUT_OK;
}

/* A Binomial(n, p) count by inversion of one uniform u in [0, 1): the CDF summed from the
 * rarer outcome's zero (its pmf (1 - q)^n, q <= 1/2, stays normal for n <= 1000). */
static int64_t binomial(int64_t n, double p, double u)
{
    if (n <= 0 || p <= 0.0)
        return 0;
    if (p >= 1.0)
        return n;
    bool flip = p > 0.5;
    double q = flip ? 1.0 - p : p, ratio = q / (1.0 - q);
    double pmf = exp((double)n * log1p(-q)), cdf = pmf;
    int64_t x = 0;
    while (u >= cdf && x < n) {
        pmf *= ratio * (double)(n - x) / (double)(x + 1);
        cdf += pmf;
        x++;
    }
    return flip ? n - x : x;
}

/* Two standard normals from two uniforms in [0, 1) (Box-Muller). */
static void normals(const double *u, double *z1, double *z2)
{
    double r = sqrt(-2.0 * log1p(-u[0])), a = 2.0 * M_PI * u[1];
    *z1 = r * cos(a);
    *z2 = r * sin(a);
}

/* The power gain of a link in a slot from its 4 uniforms: Rician small-scale fading with
 * K = rician_k (0: Rayleigh), |h|^2 with h = sqrt(K/(K+1)) + sqrt(1/(2(K+1))) (z1 + i z2),
 * mean 1 (Rice 1944; Stojanovic & Preisig 2009 for the acoustic channel), times log-normal
 * shadowing 10^(sigma z3 / 10) (median 1). 1 with fading off. */
static double link_gain(const Channel *ch, const double *u)
{
    if (!ch->fading)
        return 1.0;
    double z1, z2, z3, z4;
    normals(u, &z1, &z2);
    normals(u + 2, &z3, &z4);
    double los = sqrt(ch->rician_k / (ch->rician_k + 1.0));
    double scatter = sqrt(0.5 / (ch->rician_k + 1.0));
    double re = los + scatter * z1, im = scatter * z2;
    return (re * re + im * im) * pow(10.0, ch->shadowing_sigma_db * z3 / 10.0);
}

/* The link energies of AUV i (auv_xy (n, 2), auv_depth_m (n,) or NULL: 0) and node j of
 * `nodes` (k, 2), at their distance_m[i * k + j] (iout_link_energy). */
static void pair_energy(const Link *link, const double *auv_xy, const double *auv_depth_m,
                        const double *nodes, const double *distance_m, int64_t k, int64_t i,
                        int64_t j, double *harvest_j, double *uplink_j)
{
    iout_link_energy(link, distance_m[i * k + j], iout_horizontal_m(auv_xy + 2 * i, nodes + 2 * j),
                     auv_depth_m ? auv_depth_m[i] : 0.0, harvest_j, uplink_j);
}

/* Env e's uplinks through the channel (world/network.py states the rules). From the
 * requests (`request_j`, and `reference`: the nearest active AUV naming each node, whose
 * range sets its power; -1: none), which nodes can afford to transmit in the window the
 * handshake leaves (`paid_j`: what each pays), their SINR at the AUVs, the packets that
 * arrive, `delivered` and the delivered bits. Scales `uplink_req_j` to the window. */
static void serve_channel(const Network *net, int64_t e, int64_t n, int64_t k, const Link *link,
                          const Channel *ch, const double *auv_xy, const double *auv_depth_m,
                          const int64_t *data, int64_t node_stride,
                          const bool *active, const double *distance_m, const double *request_j,
                          const int64_t *reference, double *uplink_req_j, double *paid_j,
                          bool *delivered, const LinkOutcomes *out)
{
    const double *energy = net->energy_j + e * k, *nodes = net->nodes_m + e * k * 2;
    double *bits = net->node_bits + e * k;
    int64_t row = IOUT_CHANNEL_DRAWS(n), sent[k], received[k];
    double usable_s[k], success[k]; /* success: 1 - prod of the receiving AUVs' PER */
    for (int64_t j = 0; j < k; j++) {
        paid_j[j] = 0.0;
        sent[j] = received[j] = 0;
        success[j] = 0.0;
        if (reference[j] < 0)
            continue;
        usable_s[j] = fmax(ch->data_s - ch->delay_s_per_m * distance_m[reference[j] * k + j], 0.0);
        double cost_j = request_j[j] * (usable_s[j] / ch->data_s);
        if (usable_s[j] > 0.0 && energy[j] >= cost_j) {
            paid_j[j] = cost_j;
            sent[j] = (int64_t)floor(ch->data_rate_bps * usable_s[j] / ch->packet_bits);
        }
    }
    for (int64_t i = 0; i < n; i++) {
        int64_t j = data[i * node_stride];
        double window_s = fmax(ch->data_s - ch->delay_s_per_m * distance_m[i * k + j], 0.0);
        uplink_req_j[i] *= window_s / ch->data_s;
        out->sinr_db[i] = out->per[i] = NAN;
        if (!active[i] || paid_j[j] == 0.0)
            continue;
        /* Received power over the band's noise: a node's power makes SNR = snr_req at its
         * reference AUV, so at range d it is snr_req E_req(d_ref) / E_req(d), times the
         * link's gain (fading, shadowing). Other transmitting nodes add to the noise. */
        const double *u = out->draws + i * row + 1;
        double signal = 0.0, noise = 1.0;
        for (int64_t m = 0; m < k; m++) {
            if (paid_j[m] == 0.0 || (m != j && !ch->interference))
                continue;
            double harvest, need;
            pair_energy(link, auv_xy, auv_depth_m, nodes, distance_m, k, i, m, &harvest, &need);
            double power = ch->snr_req * (request_j[m] / need) * link_gain(ch, u + 4 * reference[m]);
            if (m == j)
                signal = power;
            else
                noise += power;
        }
        double sinr = signal / noise;
        out->sinr_db[i] = 10.0 * log10(sinr);
        out->per[i] = ch->packets ? packet_error_rate(ch, sinr) : (double)(sinr < ch->snr_req);
        success[j] = 1.0 - (1.0 - success[j]) * out->per[i];
    }
    for (int64_t j = 0; j < k; j++) {
        if (paid_j[j] == 0.0) {
            delivered[j] = false;
        } else if (ch->packets) {
            received[j] = binomial(sent[j], success[j], out->draws[reference[j] * row]);
            delivered[j] = (double)received[j] >= fmax(1.0, ceil(ch->delivery_share * (double)sent[j]));
            bits[j] += (double)received[j] * ch->packet_bits;
        } else { /* the Shannon bound: delivered when some AUV's SINR reaches snr_req */
            delivered[j] = success[j] > 0.0;
            bits[j] += delivered[j] ? ch->data_rate_bps * usable_s[j] : 0.0;
        }
    }
    for (int64_t i = 0; i < n; i++) {
        int64_t j = data[i * node_stride];
        bool linked = active[i] && paid_j[j] > 0.0;
        out->sent[i] = linked ? sent[j] : 0;
        out->received[i] = linked ? received[j] : 0;
    }
}

/* One slot of env e's nodes; the node indices must lie in [0, k) (checked by the callers). */
void iout_serve_env(const Network *net, int64_t e, int64_t n, int64_t k, const Link *link,
                    const Channel *ch, int64_t k_reset, double aoi_max, const double *auv_xy,
                    const double *auv_depth_m, const double *node_depth_m, const int64_t *wet, const int64_t *data, int64_t node_stride,
                    const bool *active, double *distance_m, bool *uplink_ok,
                    double *uplink_req_j, double *uplink_stored_j, double *harvested_j,
                    bool *delivered, const LinkOutcomes *out)
{
    const double *nodes = net->nodes_m + e * k * 2;
    double *energy = net->energy_j + e * k, *aoi = net->aoi + e * k;
    double *bits = net->node_bits + e * k;
    int64_t *count = net->service_count + e * k, *deliveries = net->deliveries + e * k;
    double request_j[k], paid_j[k]; /* the cheapest E_req of the active AUVs naming each node */
    int64_t reference[k];           /* the AUV of that E_req (-1: no active AUV named it) */
    for (int64_t j = 0; j < k; j++) {
        request_j[j] = INFINITY;
        reference[j] = -1;
        harvested_j[j] = 0.0;
    }
    iout_distances(auv_xy, auv_depth_m, n, nodes, node_depth_m, k, distance_m);
    for (int64_t i = 0; i < n; i++) {
        int64_t up = data[i * node_stride], charge = wet[i * node_stride];
        for (int64_t j = 0; j < k; j++) {
            if (j != up && j != charge)
                continue;
            double harvest, need;
            pair_energy(link, auv_xy, auv_depth_m, nodes, distance_m, k, i, j, &harvest, &need);
            if (j == up) {
                uplink_req_j[i] = need;
                uplink_stored_j[i] = energy[j];
                if (active[i] && need < request_j[j]) {
                    request_j[j] = need;
                    reference[j] = i;
                }
            }
            if (j == charge && active[i])
                harvested_j[j] += harvest;
        }
    }
    if (ch->enabled) {
        serve_channel(net, e, n, k, link, ch, auv_xy, auv_depth_m, data, node_stride, active,
                      distance_m, request_j, reference, uplink_req_j, paid_j, delivered, out);
    } else { /* the paper's: delivered when the energy stored at the start covers E_req */
        for (int64_t j = 0; j < k; j++) {
            delivered[j] = energy[j] >= request_j[j];
            paid_j[j] = delivered[j] ? request_j[j] : 0.0;
            bits[j] += delivered[j] ? link->bits_per_delivery : 0.0;
        }
    }
    for (int64_t j = 0; j < k; j++) {
        energy[j] += harvested_j[j] - paid_j[j];
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

static int64_t check_serve(const char *where, int64_t e, int64_t n_envs, int64_t n, int64_t k,
                           const int64_t *wet, const int64_t *data, int64_t node_stride)
{
    if (e < 0 || e >= n_envs || n < 1 || n > IOUT_MAX_AUVS || k < 1 || k > IOUT_MAX_NODES ||
        node_stride < 1)
        return iout_fail("%s: env %lld of %lld, %lld AUVs, %lld nodes, stride %lld; accepted an "
                         "env in [0, envs), 1 to %d AUVs, 1 to %d nodes and a stride >= 1",
                         where, (long long)e, (long long)n_envs, (long long)n, (long long)k,
                         (long long)node_stride, IOUT_MAX_AUVS, IOUT_MAX_NODES);
    for (int64_t i = 0; i < n; i++) {
        int64_t w = wet[i * node_stride], d = data[i * node_stride];
        if (w < 0 || w >= k || d < 0 || d >= k)
            return iout_fail("%s: AUV %lld names nodes %lld and %lld; accepted 0 to %lld", where,
                             (long long)i, (long long)w, (long long)d, (long long)(k - 1));
    }
    return IOUT_OK;
}

/* The network rules of one slot on their own, on the paper's channel (for their tests). */
int64_t iout_serve(const Network *net, int64_t e, int64_t n_envs, int64_t n, int64_t k,
                   const Link *link, int64_t k_reset, double aoi_max, const double *auv_xy,
                   const int64_t *wet, const int64_t *data, int64_t node_stride,
                   const bool *active, double *distance_m, bool *uplink_ok,
                   double *uplink_req_j, double *uplink_stored_j, double *harvested_j,
                   bool *delivered)
{
    static const Channel paper = {.enabled = 0};
    static const LinkOutcomes none = {0};
    int64_t status = check_serve("iout_serve", e, n_envs, n, k, wet, data, node_stride);
    if (status)
        return status;
    iout_serve_env(net, e, n, k, link, &paper, k_reset, aoi_max, auv_xy, NULL, NULL, wet, data,
                   node_stride, active, distance_m, uplink_ok, uplink_req_j, uplink_stored_j, harvested_j,
                   delivered, &none);
    return IOUT_OK;
}

/* The same through a channel, with the per-AUV link outcomes (for their tests). Every AUV
 * names node `wet[i]` to charge and `data[i]` to collect from; the depths are (n,) and (k,);
 * `draws` is (n, IOUT_CHANNEL_DRAWS(n)). */
int64_t iout_serve_channel(const Network *net, int64_t e, int64_t n_envs, int64_t n, int64_t k,
                           const Link *link, const Channel *ch, int64_t k_reset, double aoi_max,
                           const double *auv_xy, const double *auv_depth_m,
                           const double *node_depth_m, const int64_t *wet, const int64_t *data,
                           const bool *active, const double *draws, double *distance_m,
                           bool *uplink_ok, double *sinr_db, double *per, int64_t *sent,
                           int64_t *received)
{
    int64_t status = check_serve("iout_serve_channel", e, n_envs, n, k, wet, data, 1);
    if (status)
        return status;
    double req_j[n], stored_j[n], harvested_j[k];
    bool delivered[k];
    LinkOutcomes out = {draws, sinr_db, per, sent, received};
    iout_serve_env(net, e, n, k, link, ch, k_reset, aoi_max, auv_xy, auv_depth_m, node_depth_m,
                   wet, data, 1, active, distance_m, uplink_ok, req_j, stored_j, harvested_j, delivered, &out);
    return IOUT_OK;
}
