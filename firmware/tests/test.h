/* test.h - a tiny runner: cases read as sentences, one line of totals.
 *   SHOULD("answer exception 02 when ...") { ... CHECK(x == y); }
 * Each SHOULD starts from fresh simulated hardware (th_fresh). */
#ifndef FACETTE_TEST_H
#define FACETTE_TEST_H

#include <stdio.h>

#include "hal_test.h"

extern int t_passed, t_failed, t_case_bad;
extern const char *t_case;
int t_begin(const char *name);
int t_end(void);
void t_fail(const char *what, const char *file, int line);

#define SHOULD(name) for (int t_once_ = t_begin("should " name); t_once_; t_once_ = t_end())
#define CHECK(cond)                                     \
    do {                                                \
        if (!(cond))                                    \
            t_fail(#cond, __FILE__, __LINE__);          \
    } while (0)
#define CHECK_EQ(a, b)                                                                  \
    do {                                                                                \
        long long a_ = (long long)(a), b_ = (long long)(b);                             \
        if (a_ != b_) {                                                                 \
            char m_[256];                                                               \
            snprintf(m_, sizeof m_, "%s == %s (%lld != %lld)", #a, #b, a_, b_);         \
            t_fail(m_, __FILE__, __LINE__);                                             \
        }                                                                               \
    } while (0)

void test_mb(void);
void test_vectors(void);
void test_seq(void);
void test_safe(void);
void test_nvm(void);

#endif
