/* The compiled rules' shared declarations: the structs Python fills (iout_mj/native.py) and
 * the functions of world/network.c, mission/rules.c and backends/kinematic.c.
 *
 * Every array is C-contiguous with a leading batch axis of B environments (one env: B = 1);
 * the field order of each struct is the order of its Python declaration, and iout_layout()
 * states it so that native.py refuses a library whose layout differs. */
#ifndef IOUT_NATIVE_H
#define IOUT_NATIVE_H

#include <stdbool.h>
#include <stdint.h>

/* mission.rules.PARAMS_DTYPE: the constants of a config. */
typedef struct {
    double slot_s;
    int64_t horizon_slots;
    double area_x_m, area_y_m, inv_diag_per_m;
    double dock_x_m, dock_y_m, dock_radius_m;
    double v_max_mps, hotel_j, drag_power_w_at_1mps;
    int64_t k_reset;
    double aoi_max, deadline_speed_mps, fairness_lambda;
    int64_t fairness_min_deliveries;
    double stall_distance_m, margin_epsilon_j, collision_sigma_m, safety_distance_m;
    double collision_distance_m, energy_obs_ref_j, obs_high;
    /* config.RewardWeights, signed, in field order */
    double w_docking_progress, w_aoi, w_fairness, w_boundary, w_stall, w_energy_margin,
        w_infeasible_uplink, w_collision, w_dock_first_entry, w_dock_all, w_deadline,
        w_undocked_at_end;
} Params;

/* world.acoustics.LINK_DTYPE: the link budget's distance-independent constants. */
typedef struct {
    double harvest_j, uplink_j, wet_per_m, data_per_m, spreading, min_distance_m;
} Link;

/* world.network.NetworkArrays: node state, (B, K) unless noted. */
typedef struct {
    double *nodes_m; /* (B, K, 2) */
    double *energy_j, *aoi;
    int64_t *service_count, *deliveries;
    double *mean_aoi, *jain; /* (B,) */
} Network;

/* mission.state.MissionState, (B, ...) with the axes declared there. */
typedef struct {
    double *positions_m, *headings_rad, *speeds_mps, *heading_sp, *speed_sp, *straight_end_m;
    bool *boundary_attempt;
    int64_t *action;
    bool *docked;
    double *dock_dist_m, *deadline_slack_m, *distance_m, *battery_j, *propulsion_energy_j,
        *yaw_energy_j, *current_mps;
    int64_t *slot;
    double *sum_mean_aoi, *sum_objective, *aoi_after_mission, *min_separation_m;
    int64_t *collisions;
    bool *all_docked_paid;
    double *reward;
    bool *terminated, *truncated;
} State;

/* mission.state.MissionLog: (B, T + 1, ...) states, (B, T, N) links. */
typedef struct {
    double *positions_m, *headings_rad, *speeds_mps, *mean_aoi, *jain;
    int64_t *aet_nodes, *uplink_nodes;
    bool *uplink_ok;
} Log;

/* mission.core.Mission's view for the rules: sizes, constants, state, and the slot's inputs
 * and outputs. */
typedef struct {
    int64_t n_envs, n_auvs, n_nodes, n_path;
    const Params *p;
    const Link *link;
    const double *dtheta_rad, *dv_mps; /* per heading / speed index */
    State s;
    Network net;
    Log log;
    int64_t *actions; /* (B, N, 4) the slot's decoded actions */
    double *end_positions_m, *end_headings_rad, *end_speeds_mps; /* (B, N, 2), (B, N) */
    double *propulsion_energy_j, *yaw_energy_j;                  /* (B, N) of the slot */
    double *path_m;                                              /* (S, B, N, 2), S = n_path */
    double *terms;                                               /* (B, 12) reward terms */
    double *obs;                                                 /* (B, D) observation */
} Mission;

/* What a slot did, as the reward terms read it (mission/rewards.c); per AUV arrays are (N,). */
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

#define N_REWARD_TERMS 12

const char *iout_layout(void);

/* world/network.c */
void iout_link_energies(const Link *link, double distance_m, double *harvest_j, double *uplink_j);
void iout_link_energies_each(const Link *link, const double *distance_m, int64_t count,
                             double *harvest_j, double *uplink_j);
double iout_jain(const int64_t *counts, int64_t k);
void iout_distances(const double *auv_xy, int64_t n, const double *nodes_m, int64_t k,
                    double *distance_m);
void iout_summarise(const Network *net, int64_t n_envs, int64_t k);
void iout_serve(const Network *net, int64_t e, int64_t n, int64_t k, const Link *link,
                int64_t k_reset, double aoi_max, const double *auv_xy, const int64_t *wet,
                const int64_t *data, int64_t node_stride, const bool *active,
                double *distance_m, bool *uplink_ok, double *uplink_req_j,
                double *uplink_stored_j, double *harvested_j, bool *delivered);

/* mission/rewards.c */
double iout_slot_terms(const Params *p, const SlotContext *c, double *out);

/* mission/rules.c */
int64_t iout_first_bad_action(const int64_t *actions, int64_t count, const int64_t *high,
                              int64_t width);
void iout_begin_env(const Mission *m, int64_t e);
void iout_begin_slot(const Mission *m);
void iout_end_env(const Mission *m, int64_t e, const double *positions_m,
                  const double *headings_rad, const double *speeds_mps,
                  const double *propulsion_energy_j, const double *yaw_energy_j,
                  const double *path_m, int64_t path_stride, int64_t n_path);
void iout_end_slot(const Mission *m);
void iout_start(const Mission *m, const bool *restarted);
void iout_observe(const Mission *m);
double iout_unserved_aoi_sum(const Params *p, int64_t slot, const double *aoi, int64_t k);
double iout_node_energy_level(double energy_j, double ref_j, double high);
void iout_node_energy_levels(const double *energy_j, int64_t count, double ref_j, double high,
                             double *out);
bool iout_in_area(const Params *p, double x, double y);

/* backends/kinematic.c */
void iout_kinematic_slot(const Mission *m);

#endif
