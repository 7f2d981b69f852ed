/* The exported tables of native.h's declarations (names, types, offsets, sizes) and the
 * error text of the last failed call. */
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>

#include "native.h"

#define VALUE(owner, type, name) {#owner, #name, #type, "value", offsetof(owner, name), sizeof(type)},
#define POINTER(owner, type, name) {#owner, #name, #type, "pointer", offsetof(owner, name), sizeof(void *)},
#define STRUCT(owner, type, name) {#owner, #name, #type, "struct", offsetof(owner, name), sizeof(type)},
#define ARRAY(owner, type, name, count) {#owner, #name, #type, "array", offsetof(owner, name), sizeof(type) * (count)},
#define SIZEOF(owner) {#owner, "", #owner, "sizeof", 0, sizeof(owner)},

#define PARAMS_VALUE(type, name) VALUE(Params, type, name)
#define LINK_VALUE(type, name) VALUE(Link, type, name)
#define LINK_ARRAY(type, name, count) ARRAY(Link, type, name, count)
#define CHANNEL_VALUE(type, name) VALUE(Channel, type, name)
#define NETWORK_POINTER(type, name) POINTER(Network, type, name)
#define STATE_POINTER(type, name) POINTER(State, type, name)
#define LOG_POINTER(type, name) POINTER(Log, type, name)
#define MISSION_VALUE(type, name) VALUE(Mission, type, name)
#define MISSION_POINTER(type, name) POINTER(Mission, type, name)
#define MISSION_STRUCT(type, name) STRUCT(Mission, type, name)

static const IoutDecl DECLS[] = {
    IOUT_PARAMS(PARAMS_VALUE) SIZEOF(Params)
    IOUT_LINK(LINK_VALUE) IOUT_LINK_ARRAYS(LINK_ARRAY) SIZEOF(Link)
    IOUT_CHANNEL(CHANNEL_VALUE) SIZEOF(Channel)
    IOUT_NETWORK(NETWORK_POINTER) SIZEOF(Network)
    IOUT_STATE(STATE_POINTER) SIZEOF(State)
    IOUT_LOG(LOG_POINTER) SIZEOF(Log)
    IOUT_MISSION_SIZES(MISSION_VALUE)
    IOUT_MISSION_CONSTANTS(MISSION_POINTER)
    IOUT_MISSION_STRUCTS(MISSION_STRUCT)
    IOUT_MISSION_IO(MISSION_POINTER)
    SIZEOF(Mission)
};

int64_t iout_decls(const IoutDecl **table)
{
    *table = DECLS;
    return (int64_t)(sizeof DECLS / sizeof DECLS[0]);
}

#define GROUP(name, per_auv, per_node, per_pair, fixed) {#name, per_auv, per_node, per_pair, fixed},
static const IoutGroup GROUPS[] = {IOUT_OBSERVATION(GROUP)};

int64_t iout_groups(const IoutGroup **table)
{
    *table = GROUPS;
    return (int64_t)(sizeof GROUPS / sizeof GROUPS[0]);
}

#define TOKEN(part, name, fixed, per_auv) {#part, #name, fixed, per_auv},
static const IoutToken TOKENS[] = {IOUT_TOKENS(TOKEN)};

int64_t iout_tokens(const IoutToken **table)
{
    *table = TOKENS;
    return (int64_t)(sizeof TOKENS / sizeof TOKENS[0]);
}

#define TERM_NAME(name) #name,
static const char *const TERMS[] = {IOUT_REWARD_TERMS(TERM_NAME)};

int64_t iout_terms(const char *const **names)
{
    *names = TERMS;
    return N_REWARD_TERMS;
}

static _Thread_local char error_text[512];

const char *iout_error(void) { return error_text; }

int64_t iout_fail(const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(error_text, sizeof error_text, format, args);
    va_end(args);
    return IOUT_EINVAL;
}
