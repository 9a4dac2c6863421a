/* vectors.c - the golden frames of protocol/vectors/ (*.hex), byte for byte.
 * Run from the repository root (the Makefile does). */
#include <stdlib.h>
#include <string.h>

#include "test.h"

static size_t parse_hex(const char *s, uint8_t *out, size_t cap)
{
    size_t n = 0;
    while (*s && n < cap) {
        while (*s == ' ' || *s == '\t')
            s++;
        if (!s[0] || s[0] == '\n' || s[0] == '-')
            break;
        char byte[3] = {s[0], s[1], 0};
        out[n++] = (uint8_t)strtoul(byte, NULL, 16);
        s += 2;
    }
    return n;
}

static void run_file(const char *name)
{
    char path[256];
    snprintf(path, sizeof path, "protocol/vectors/%s", name);
    FILE *f = fopen(path, "r");
    CHECK(f != NULL);
    if (!f)
        return;
    char line[1024], desc[1024] = "";
    uint8_t req[300], want[300], got[300];
    size_t nreq = 0;
    int pairs = 0;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#') {
            snprintf(desc, sizeof desc, "%s", line + 2);
            desc[strcspn(desc, "\n")] = 0;
        } else if (line[0] == '>') {
            nreq = parse_hex(line + 1, req, sizeof req);
        } else if (line[0] == '<') {
            size_t nwant = parse_hex(line + 1, want, sizeof want);
            size_t ngot = th_transact(req, nreq, got);
            pairs++;
            if (ngot != nwant || memcmp(got, want, ngot) != 0) {
                char m[1400];
                int k = snprintf(m, sizeof m, "%s: %s: got", name, desc);
                for (size_t i = 0; i < ngot && k < 1300; i++)
                    k += snprintf(m + k, sizeof m - (size_t)k, " %02X", got[i]);
                if (!ngot)
                    snprintf(m + k, sizeof m - (size_t)k, " no answer");
                t_fail(m, __FILE__, __LINE__);
            }
        }
    }
    fclose(f);
    CHECK(pairs > 5);
}

void test_vectors(void)
{
    SHOULD("answer every request of protocol/vectors/functions.hex byte for byte")
        run_file("functions.hex");
    SHOULD("answer every request of protocol/vectors/exceptions.hex byte for byte")
        run_file("exceptions.hex");
    SHOULD("follow protocol/vectors/addressing.hex (broadcast, unit id, CRC) byte for byte")
        run_file("addressing.hex");
}
