/* The compiled rules' one declaration of everything C and Python share: the structs, the
 * reward terms and the observation groups, each as an X-macro list that expands here to the
 * C struct and, in native.c, to a table of names, types, offsets and sizes that the library
 * exports (iout_decls, iout_groups, iout_terms, iout_tokens). Python (iout_mj/native.py) builds its views from that
 * table, by name and offset, and refuses at import a library whose fields differ from its own
 * arrays in name or element type: field order is free, drift is loud.
 *
 * Every array is C-contiguous with a leading batch axis of B environments (one env: B = 1).
 * Every exported function (IOUT_API) checks what it is handed and returns IOUT_OK or an error
 * code, with the details in iout_error(); Python turns them into exceptions. */
#ifndef IOUT_NATIVE_H
#define IOUT_NATIVE_H

#include <stdbool.h>
#include <stdint.h>

#define IOUT_API __attribute__((visibility("default")))
/* Bounds of the sizes C accepts (stack arrays are sized by them); configs allow far less. */
#define IOUT_MAX_AUVS 64
#define IOUT_MAX_NODES 4096

/* ----------------------------------------------------------------- declarations */
/* Params: the constants of a config (mission.rules.params). X(type, name). */
#define IOUT_PARAMS(X)                                                                          \
    X(double, slot_s) X(int64_t, horizon_slots) X(double, area_x_m) X(double, area_y_m)         \
    X(double, inv_diag_per_m) X(double, dock_x_m) X(double, dock_y_m) X(double, dock_radius_m)  \
    X(double, dock_max_speed_mps)                                                               \
    X(double, v_max_mps) X(double, hotel_j) X(double, drag_power_w_at_1mps)                     \
    X(int64_t, k_reset) X(double, aoi_max) X(double, deadline_speed_mps)                        \
    X(double, fairness_lambda) X(int64_t, fairness_min_deliveries) X(double, stall_distance_m)  \
    X(double, margin_epsilon_j) X(double, collision_sigma_m) X(double, safety_distance_m)       \
    X(double, collision_distance_m) X(double, energy_obs_ref_j) X(double, obs_high)             \
    IOUT_REWARD_WEIGHTS(X)

/* The signed reward weights, config.RewardWeights's fields with a w_ prefix. */
#define IOUT_REWARD_WEIGHTS(X)                                                                  \
    X(double, w_docking_progress) X(double, w_aoi) X(double, w_fairness) X(double, w_boundary)  \
    X(double, w_stall) X(double, w_energy_margin) X(double, w_infeasible_uplink)                \
    X(double, w_collision) X(double, w_dock_first_entry) X(double, w_dock_all)                  \
    X(double, w_deadline) X(double, w_undocked_at_end)

/* Link: the link budget's distance-independent constants (world.acoustics.LinkBudget), and a
 * site-specific transmission-loss table (world.tl_table) that stands for spreading and
 * absorption where tl_ranges > 0: TL in dB, depth-major (tl_*_db[d * tl_ranges + r]), at the
 * AET (wet) and data frequencies, over tl_depths AUV depths and tl_ranges horizontal ranges.
 * X(type, name) for values, X(type, name, count) for fixed-size arrays. */
#define IOUT_TL_MAX_RANGES 2048
#define IOUT_TL_MAX_DEPTHS 128
#define IOUT_TL_MAX_CELLS 16384 /* depths x ranges of one frequency */
#define IOUT_LINK(X)                                                                            \
    X(double, harvest_j) X(double, uplink_j) X(double, wet_per_m) X(double, data_per_m)         \
    X(double, spreading) X(double, min_distance_m) X(double, bits_per_delivery)                 \
    X(int64_t, tl_ranges) X(int64_t, tl_depths)
#define IOUT_LINK_ARRAYS(X)                                                                     \
    X(double, tl_range_m, IOUT_TL_MAX_RANGES) X(double, tl_depth_m, IOUT_TL_MAX_DEPTHS)          \
    X(double, tl_wet_db, IOUT_TL_MAX_CELLS) X(double, tl_data_db, IOUT_TL_MAX_CELLS)

/* Channel: the acoustic network layer's constants (world.acoustics.ChannelConstants); every
 * feature off (enabled 0) is the paper's channel. Flags are 0 or 1; fading is Rician with
 * K = rician_k (0: Rayleigh). The depths are the Mission's auv_depth_m and node_depth_m. */
#define IOUT_CHANNEL(X)                                                                         \
    X(int64_t, enabled) X(double, delay_s_per_m) X(double, data_s)                              \
    X(double, data_rate_bps) X(int64_t, packets) X(double, packet_bits)                         \
    X(double, delivery_share) X(int64_t, modulation) X(double, ebn0_per_snr) X(double, snr_req) \
    X(int64_t, interference) X(int64_t, fading) X(double, rician_k)                             \
    X(double, shadowing_sigma_db)
/* Modulations (channel.modulation): their BER in AWGN is in world/network.c. */
enum { IOUT_BPSK = 0, IOUT_BFSK = 1 };
/* Uniform draws per AUV and slot in Mission.channel_draws: the packet draw of the node it
 * collects from, then 4 per transmitter (two Box-Muller pairs: fading, shadowing). */
#define IOUT_CHANNEL_DRAWS(n_auvs) (1 + 4 * (n_auvs))

/* Network: pointers to the node state, (B, K) unless noted (world.network.SensorNetwork).
 * X(element type, name). */
#define IOUT_NETWORK(X)                                                                         \
    X(double, nodes_m) /* (B, K, 2) */                                                          \
    X(double, energy_j) X(double, aoi) X(int64_t, service_count) X(int64_t, deliveries)         \
    X(double, mean_aoi) X(double, jain) /* (B,) */                                            \
    X(double, node_bits)

/* State: pointers to mission.state.MissionState's arrays, with the axes declared there. */
#define IOUT_STATE(X)                                                                           \
    X(double, positions_m) X(double, headings_rad) X(double, speeds_mps) X(double, heading_sp)  \
    X(double, speed_sp) X(double, straight_end_m) X(bool, boundary_attempt) X(int64_t, action)  \
    X(bool, docked) X(double, dock_dist_m) X(double, deadline_slack_m) X(double, distance_m)    \
    X(double, battery_j) X(double, propulsion_energy_j) X(double, yaw_energy_j)                 \
    X(double, current_mps) X(int64_t, slot) X(double, sum_mean_aoi) X(double, sum_objective)    \
    X(double, aoi_after_mission) X(double, min_separation_m) X(int64_t, collisions)             \
    X(bool, all_docked_paid) X(double, reward) X(bool, terminated) X(bool, truncated)

/* Log: pointers to mission.state.MissionLog's arrays: (B, T + 1, ...) states, (B, T, N) links. */
#define IOUT_LOG(X)                                                                             \
    X(double, positions_m) X(double, headings_rad) X(double, speeds_mps) X(double, mean_aoi)    \
    X(double, jain) X(int64_t, aet_nodes) X(int64_t, uplink_nodes) X(bool, uplink_ok)

/* Mission, the one argument of the slot functions (mission.core.Mission's private view):
 * sizes (the bounds every check uses), constants, the state, and the slot's inputs and
 * outputs. */
#define IOUT_MISSION_SIZES(X)                                                                   \
    X(int64_t, n_envs) X(int64_t, n_auvs) X(int64_t, n_nodes) X(int64_t, horizon_slots)         \
    X(int64_t, heading_levels) X(int64_t, speed_levels) X(int64_t, n_obs) X(int64_t, n_path)
#define IOUT_MISSION_CONSTANTS(X)                                                               \
    X(const Params, p) X(const Link, link) X(const Channel, channel)                            \
    X(const double, dtheta_rad) /* (heading_levels,) */                                         \
    X(const double, dv_mps)     /* (speed_levels,) */                                           \
    X(const double, auv_depth_m)  /* (N,) below the surface; zeros with depth off */             \
    X(const double, node_depth_m) /* (K,) of each node's seabed; zeros with depth off */
#define IOUT_MISSION_STRUCTS(X) X(State, s) X(Network, net) X(Log, log)
#define IOUT_MISSION_IO(X)                                                                      \
    X(int64_t, actions)           /* (B, N, 4) the slot's decoded actions */                    \
    X(double, end_positions_m)    /* (B, N, 2) */                                               \
    X(double, end_headings_rad)   /* (B, N) */                                                  \
    X(double, end_speeds_mps)     /* (B, N) */                                                  \
    X(double, propulsion_energy_j) /* (B, N) of the slot */                                     \
    X(double, yaw_energy_j)       /* (B, N) of the slot */                                      \
    X(double, path_m)             /* (S, B, N, 2), S = n_path */                                \
    X(double, terms)              /* (B, reward terms) */                                       \
    X(double, obs)                /* (B, n_obs) */                                              \
    X(double, channel_draws)      /* (B, N, IOUT_CHANNEL_DRAWS(N)) uniforms in [0, 1) */        \
    X(double, link_sinr_db)       /* (B, N) of the uplink each AUV collects (NaN: none) */      \
    X(double, link_per)           /* (B, N) its packet error rate (NaN: none) */                \
    X(int64_t, link_packets_sent) /* (B, N) by the node it collects from */                     \
    X(int64_t, link_packets_received) /* (B, N) of those, arrived at any AUV */

/* The reward terms, in the order of the mission's term array (mission.rewards). */
#define IOUT_REWARD_TERMS(X)                                                                    \
    X(docking_progress) X(aoi) X(fairness) X(boundary) X(stall) X(energy_margin)                \
    X(infeasible_uplink) X(collision) X(docking) X(deadline) X(undocked_at_end)                 \
    X(aoi_after_mission)

/* The observation groups, in order, with their sizes for N AUVs and K nodes:
 * X(name, per AUV, per node, per AUV-node pair, fixed) (mission.observation documents them). */
#define IOUT_OBSERVATION(X)                                                                     \
    X(auv_position, 2, 0, 0, 0) X(auv_heading, 2, 0, 0, 0) X(auv_speed, 1, 0, 0, 0)             \
    X(docked, 1, 0, 0, 0) X(aoi, 0, 1, 0, 0) X(node_energy, 0, 1, 0, 0)                         \
    X(distance, 0, 0, 1, 0) X(dock_distance, 1, 0, 0, 0) X(time_remaining, 0, 0, 0, 1)

/* The token observation of the general policies (mission.tokens), float32, per env:
 * [global][N AUV tokens][K_max node tokens, zeros past K][K_max node mask]. Each entry's size
 * is `fixed + per_auv * M`, with M = N - 1 in an AUV token (the other AUVs) and M = N in a
 * node token (every AUV). X(part, name, fixed, per AUV) (mission.tokens documents them). */
#define IOUT_TOKENS(X)                                                                          \
    X(global, time_remaining, 1, 0) X(global, node_share, 1, 0) X(global, mean_aoi, 1, 0)      \
    X(auv, position, 2, 0) X(auv, heading_setpoint, 2, 0) X(auv, speed, 1, 0)                  \
    X(auv, speed_setpoint, 1, 0) X(auv, docked, 1, 0) X(auv, dock_distance, 1, 0)              \
    X(auv, dock_bearing, 2, 0) X(auv, docking_slack, 1, 0) X(auv, other_auvs, 0, 3)            \
    X(node, position, 2, 0) X(node, aoi, 1, 0) X(node, reset_progress, 1, 0)                   \
    X(node, energy, 1, 0) X(node, auv_links, 0, 4)

/* ----------------------------------------------------------------- the structs */
#define IOUT_VALUE_FIELD(type, name) type name;
#define IOUT_POINTER_FIELD(type, name) type *name;
#define IOUT_ARRAY_FIELD(type, name, count) type name[count];

typedef struct { IOUT_PARAMS(IOUT_VALUE_FIELD) } Params;
typedef struct { IOUT_LINK(IOUT_VALUE_FIELD) IOUT_LINK_ARRAYS(IOUT_ARRAY_FIELD) } Link;
typedef struct { IOUT_CHANNEL(IOUT_VALUE_FIELD) } Channel;
typedef struct { IOUT_NETWORK(IOUT_POINTER_FIELD) } Network;
typedef struct { IOUT_STATE(IOUT_POINTER_FIELD) } State;
typedef struct { IOUT_LOG(IOUT_POINTER_FIELD) } Log;
typedef struct {
    IOUT_MISSION_SIZES(IOUT_VALUE_FIELD)
    IOUT_MISSION_CONSTANTS(IOUT_POINTER_FIELD)
    IOUT_MISSION_STRUCTS(IOUT_VALUE_FIELD)
    IOUT_MISSION_IO(IOUT_POINTER_FIELD)
} Mission;

#define IOUT_COUNT(...) +1
enum { N_REWARD_TERMS = 0 IOUT_REWARD_TERMS(IOUT_COUNT) };

/* What a slot did, as the reward terms read it (mission/rewards.c; internal to C). Per AUV
 * arrays are (N,). */
typedef struct {
    int64_t n_auvs;
    const bool *active;           /* not docked at the start of the slot */
    const double *moved_m;        /* displacement over the slot */
    const bool *boundary_attempt; /* the slot's straight move would have left the area */
    const double *positions_m;    /* (N, 2) at the end of the slot */
    const bool *docked;           /* at the end of the slot */
    bool all_docked_first;        /* every AUV docked, for the first time in the episode */
    const double *dock_dist_before_m, *dock_dist_m;
    const double *slack_before_m, *slack_m; /* deadline slack before and after */
    double mean_aoi, jain;
    int64_t deliveries;                          /* so far, all nodes */
    const double *uplink_stored_j, *uplink_req_j; /* at the node each AUV collects from */
    bool ending;                                  /* the episode ends with this slot */
    double aoi_after_mission; /* mean-AoI sum of the unserved slots left until T_max */
} SlotContext;

/* A slot's per-AUV link outcomes of the channel (Mission's link_* outputs of one env). */
typedef struct {
    const double *draws; /* (N, IOUT_CHANNEL_DRAWS(N)) */
    double *sinr_db, *per;
    int64_t *sent, *received;
} LinkOutcomes;

/* ----------------------------------------------------------------- the exported table */
typedef struct {
    const char *owner; /* struct name */
    const char *name;  /* field name; "" for the struct's own size */
    const char *type;  /* C element type ("double", "int64_t", "bool", a struct name) */
    const char *kind;  /* "value", "array", "pointer", "struct" or "sizeof" */
    int64_t offset, size; /* an array's size: of all its elements */
} IoutDecl;

typedef struct {
    const char *name;
    int64_t per_auv, per_node, per_pair, fixed;
} IoutGroup;

typedef struct {
    const char *part, *name;
    int64_t fixed, per_auv;
} IoutToken;

/* ----------------------------------------------------------------- errors */
enum { IOUT_OK = 0, IOUT_EINVAL = 1, IOUT_EACTION = 2 };
/* Record an error (printf format) for iout_error(); returns IOUT_EINVAL. */
int64_t iout_fail(const char *format, ...) __attribute__((format(printf, 1, 2)));
/* Checks of a Mission shared by every entry point (rules.c). */
int64_t iout_check_mission(const Mission *m, bool actions, bool state_actions);

/* ----------------------------------------------------------------- exported functions */
IOUT_API int64_t iout_decls(const IoutDecl **table);
IOUT_API int64_t iout_groups(const IoutGroup **table);
IOUT_API int64_t iout_tokens(const IoutToken **table);
IOUT_API int64_t iout_terms(const char *const **names);
IOUT_API const char *iout_error(void);

/* world/network.c */
IOUT_API int64_t iout_link_energies(const Link *link, const double *distance_m, int64_t count,
                                    double *harvest_j, double *uplink_j);
IOUT_API int64_t iout_link_pair_energies(const Link *link, const double *horizontal_m,
                                         const double *auv_depth_m, const double *node_depth_m,
                                         int64_t count, double *harvest_j, double *uplink_j);
IOUT_API int64_t iout_summarise(const Network *net, int64_t n_envs, int64_t k);
IOUT_API int64_t iout_serve(const Network *net, int64_t e, int64_t n_envs, int64_t n,
                            int64_t k, const Link *link, int64_t k_reset, double aoi_max,
                            const double *auv_xy, const int64_t *wet, const int64_t *data,
                            int64_t node_stride, const bool *active, double *distance_m,
                            bool *uplink_ok, double *uplink_req_j, double *uplink_stored_j,
                            double *harvested_j, bool *delivered);
IOUT_API int64_t iout_serve_channel(const Network *net, int64_t e, int64_t n_envs, int64_t n,
                                    int64_t k, const Link *link, const Channel *ch,
                                    int64_t k_reset, double aoi_max, const double *auv_xy,
                                    const double *auv_depth_m, const double *node_depth_m,
                                    const int64_t *wet, const int64_t *data, const bool *active,
                                    const double *draws, double *distance_m, bool *uplink_ok,
                                    double *sinr_db, double *per, int64_t *sent,
                                    int64_t *received);
IOUT_API int64_t iout_francois_garrison(const double *f_khz, int64_t count,
                                        double temperature_degc, double salinity_ppt,
                                        double depth_m, double ph, double *alpha_db_per_km);
IOUT_API int64_t iout_tl_interpolate(const double *range_m, int64_t n_range,
                                    const double *depth_m, int64_t n_depth, const double *tl_db,
                                    const double *at_range_m, const double *at_depth_m,
                                    int64_t count, double *out_db);
double iout_tl_at(const double *range_m, int64_t n_range, const double *depth_m, int64_t n_depth,
                  const double *tl_db, double range, double depth);
IOUT_API int64_t iout_packet_error_rates(const Channel *ch, const double *sinr, int64_t count,
                                         double *per);
void iout_link_energy(const Link *link, double distance_m, double horizontal_m,
                      double auv_depth_m, double *harvest_j, double *uplink_j);
double iout_horizontal_m(const double *auv_xy, const double *node_xy);
double iout_jain(const int64_t *counts, int64_t k);
void iout_distances(const double *auv_xy, const double *auv_depth_m, int64_t n,
                    const double *nodes_m, const double *node_depth_m, int64_t k,
                    double *distance_m);
void iout_serve_env(const Network *net, int64_t e, int64_t n, int64_t k, const Link *link,
                    const Channel *ch, int64_t k_reset, double aoi_max, const double *auv_xy,
                    const double *auv_depth_m, const double *node_depth_m,
                    const int64_t *wet, const int64_t *data, int64_t node_stride,
                    const bool *active, double *distance_m, bool *uplink_ok,
                    double *uplink_req_j, double *uplink_stored_j, double *harvested_j,
                    bool *delivered, const LinkOutcomes *out);

/* mission/rewards.c */
double iout_slot_terms(const Params *p, const SlotContext *c, double *out);

/* mission/rules.c */
IOUT_API int64_t iout_begin_slot(const Mission *m);
IOUT_API int64_t iout_end_slot(const Mission *m);
IOUT_API int64_t iout_start(const Mission *m, const bool *restarted);
IOUT_API int64_t iout_observe(const Mission *m);
IOUT_API int64_t iout_unserved_aoi_sum(const Params *p, int64_t slot, const double *aoi,
                                       int64_t k, double *out);
IOUT_API int64_t iout_node_energy_levels(const double *energy_j, int64_t count, double ref_j,
                                         double high, double *out);
void iout_begin_env(const Mission *m, int64_t e);
void iout_end_env(const Mission *m, int64_t e, const double *positions_m,
                  const double *headings_rad, const double *speeds_mps,
                  const double *propulsion_energy_j, const double *yaw_energy_j,
                  const double *path_m, int64_t path_stride, int64_t n_path);
double iout_unserved_aoi(const Params *p, int64_t slot, const double *aoi, int64_t k);
double iout_node_energy_level(double energy_j, double ref_j, double high);
bool iout_in_area(const Params *p, double x, double y);
double iout_wrap_angle(double angle_rad);

/* mission/tokens.c */
IOUT_API int64_t iout_observe_tokens(const Mission *m, int64_t k_max, double eta_speed_mps,
                                     float *out, int64_t out_size);

/* backends/kinematic.c */
IOUT_API int64_t iout_kinematic_slot(const Mission *m);

#endif
