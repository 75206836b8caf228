/* One CANopen node's object dictionary: a table made by gen/eds.py from an EDS or DCF (the build's
 * own drive, firmware/protocol/cia402_servo.eds, compiled in; any other drive's file loaded with
 * arm_sim --od) and this node's values. Reads and writes check what the file says (existence,
 * access, length, limits, for every CiA 301 basic data type); what depends on the drive's state
 * (PDO mappings, the mode of operation) is the node's to check (sim_canopen_node.c). */
#ifndef ARM_SIM_CANOPEN_OD_H
#define ARM_SIM_CANOPEN_OD_H

#include <stddef.h>
#include <stdint.h>

/* CiA 301 SDO abort codes. */
#define SIM_CO_ABORT_TOGGLE 0x05030000u
#define SIM_CO_ABORT_TIMEOUT 0x05040000u
#define SIM_CO_ABORT_COMMAND 0x05040001u
#define SIM_CO_ABORT_NO_MEMORY 0x05040005u
#define SIM_CO_ABORT_UNSUPPORTED_ACCESS 0x06010000u
#define SIM_CO_ABORT_WRITE_ONLY 0x06010001u
#define SIM_CO_ABORT_READ_ONLY 0x06010002u
#define SIM_CO_ABORT_NO_OBJECT 0x06020000u
#define SIM_CO_ABORT_NOT_MAPPABLE 0x06040041u
#define SIM_CO_ABORT_PDO_LENGTH 0x06040042u
#define SIM_CO_ABORT_LENGTH 0x06070010u
#define SIM_CO_ABORT_NO_SUB 0x06090011u
#define SIM_CO_ABORT_RANGE 0x06090030u
#define SIM_CO_ABORT_STATE 0x08000022u

#define SIM_CO_OD_MAX 2048u    /* entries of one dictionary (a large vendor file has about 1000) */
#define SIM_CO_TEXT_MAX 16384u /* bytes of a dictionary's string and domain defaults */
#define SIM_CO_HASH_BITS 12u   /* 4096 slots, twice SIM_CO_OD_MAX: short probe runs */
#define SIM_CO_HASH_SLOTS (1u << SIM_CO_HASH_BITS)
#define SIM_CO_VALUE_MAX 256u  /* the longest value an SDO moves */
#define SIM_CO_STR_SLOTS 16u   /* string objects a node keeps written values of */

/* How a value is read (gen/eds.py TYPES' kinds). */
typedef enum {
    SIM_CO_K_BOOL = 0, SIM_CO_K_INT, SIM_CO_K_UINT, SIM_CO_K_FLOAT, SIM_CO_K_TEXT, SIM_CO_K_BYTES
} sim_co_kind_t;
/* The file's access types: rww maps to RPDOs only, rwr to TPDOs only (CiA 306). */
typedef enum {
    SIM_CO_A_RO = 0, SIM_CO_A_RW, SIM_CO_A_WO, SIM_CO_A_CONST, SIM_CO_A_RWW, SIM_CO_A_RWR
} sim_co_access_t;

typedef struct {
    uint16_t index;
    uint8_t sub;
    uint8_t type;       /* CiA 301 data type, 0x01..0x1B */
    uint8_t kind;       /* sim_co_kind_t */
    uint8_t size;       /* bytes of a number; 0: a string or domain */
    uint8_t access;     /* sim_co_access_t */
    uint8_t pdo;        /* PDOMapping=1 */
    uint8_t nodeid_rel; /* the default plus the node id ($NODEID) */
    uint8_t has_low, has_high;
    uint64_t def, low, high; /* raw bits: two's complement, IEEE 754 */
    uint32_t text_off, text_len; /* a string's default: its bytes in the table's text */
} sim_co_entry_t;

typedef struct {
    unsigned n;                       /* entries, sorted by index and sub-index */
    uint32_t key[SIM_CO_OD_MAX];      /* index << 8 | sub of each, sorted */
    uint16_t slot[SIM_CO_HASH_SLOTS]; /* row + 1 of the key hashed there (0: none): a drive reads its
                                         objects every period, a lookup costs a probe or two */
    sim_co_entry_t e[SIM_CO_OD_MAX];
    unsigned text_len;
    uint8_t text[SIM_CO_TEXT_MAX];
} sim_co_table_t;

/* The build's own drive's table, as gen/eds.py writes it (sim_co_od_builtin.c). */
extern const char SIM_CO_OD_BUILTIN[];

/* A table from gen/eds.py's text; -1 with one line naming the line that is wrong. */
int sim_co_table_parse(sim_co_table_t *t, const char *text, char *err, size_t cap);
/* The same from a file (arm_sim --od). */
int sim_co_table_load(sim_co_table_t *t, const char *path, char *err, size_t cap);
/* The built-in table, parsed once (NULL only if the build's own table were broken). */
const sim_co_table_t *sim_co_table_builtin(void);
/* The row of (index, sub), or -1 with the abort code (no object / no sub-index). */
int sim_co_table_find(const sim_co_table_t *t, uint16_t index, uint8_t sub, uint32_t *abort_code);

typedef struct {
    const sim_co_table_t *t;
    uint8_t node_id;
    uint64_t value[SIM_CO_OD_MAX]; /* numbers: raw bits; strings: 0 the default, k + 1 written slot k */
    unsigned n_str;
    uint16_t str_len[SIM_CO_STR_SLOTS];
    uint8_t str[SIM_CO_STR_SLOTS][SIM_CO_VALUE_MAX];
} sim_co_od_t;

/* Every value to its default (comm_only: the communication area 0x1000..0x1FFF only, as NMT
 * reset communication does). */
void sim_co_od_reset(sim_co_od_t *od, const sim_co_table_t *t, uint8_t node_id, int comm_only);
int sim_co_od_find(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint32_t *abort_code);
int sim_co_od_has(const sim_co_od_t *od, uint16_t index, uint8_t sub);
/* A number the drive itself reads or sets (no access check); an entry the file lacks reads 0. */
uint64_t sim_co_od_get(const sim_co_od_t *od, uint16_t index, uint8_t sub);
int64_t sim_co_od_get_signed(const sim_co_od_t *od, uint16_t index, uint8_t sub);
void sim_co_od_set(sim_co_od_t *od, uint16_t index, uint8_t sub, uint64_t raw);
/* SDO upload: the value's bytes; 0 or the abort code. */
uint32_t sim_co_od_read(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap,
                        unsigned *len);
/* SDO download, checked against the file only (access, length, limits). A number: 0 and its raw
 * value, set by the caller once the node accepts it; a string or domain is stored here (*is_string
 * = 1). Else the abort code. */
uint32_t sim_co_od_check_write(sim_co_od_t *od, uint16_t index, uint8_t sub, const uint8_t *data, unsigned len,
                               uint64_t *raw, int *is_string);

#endif
