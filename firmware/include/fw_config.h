/*
 * fw_config.h - every build option of the facette firmware, one line each.
 * Override any of them with -D on the compiler command line.
 */
#ifndef FACETTE_FW_CONFIG_H
#define FACETTE_FW_CONFIG_H

#ifndef FW_CFG_MB_UNIT_ID
#define FW_CFG_MB_UNIT_ID 1u              /* Modbus unit id answered (0 = broadcast) */
#endif
#ifndef FW_CFG_MB_MAX_FRAME
#define FW_CFG_MB_MAX_FRAME 256u          /* largest RTU frame (spec: 256 bytes) */
#endif
#ifndef FW_CFG_MB_T15_CHECK
#define FW_CFG_MB_T15_CHECK 1             /* drop frames with an inner gap > 1.5 chars */
#endif
#ifndef FW_CFG_MAX_LEDS
#define FW_CFG_MAX_LEDS 16u               /* LED channels (switches on the sink) */
#endif
#ifndef FW_CFG_MAX_EXPOSURES
#define FW_CFG_MAX_EXPOSURES 16u          /* exposures per light in one scan */
#endif
#ifndef FW_CFG_RING_LEN
#define FW_CFG_RING_LEN 16u               /* frame-ring records the host can read back */
#endif
#ifndef FW_CFG_FAULT_LOG_LEN
#define FW_CFG_FAULT_LOG_LEN 8u           /* latched-fault log entries */
#endif
#ifndef FW_CFG_HARD_MAX_MA
#define FW_CFG_HARD_MAX_MA 1500u          /* absolute LED current limit, mA */
#endif
#ifndef FW_CFG_HARD_MAX_PULSE_US
#define FW_CFG_HARD_MAX_PULSE_US 30000000u /* absolute LED on-time limit per pulse, us */
#endif
#ifndef FW_CFG_DAC_MAX_CODE
#define FW_CFG_DAC_MAX_CODE 4095u         /* 12-bit DAC */
#endif
#ifndef FW_CFG_DAC_FULL_SCALE_MA
#define FW_CFG_DAC_FULL_SCALE_MA 2000u    /* sink current at FW_CFG_DAC_MAX_CODE, mA */
#endif
#ifndef FW_CFG_SENSE_OPEN_PCT
#define FW_CFG_SENSE_OPEN_PCT 50u         /* measured < this % of set: LED open */
#endif
#ifndef FW_CFG_SENSE_SHORT_PCT
#define FW_CFG_SENSE_SHORT_PCT 125u       /* measured > this % of set: LED short */
#endif
#ifndef FW_CFG_SENSE_MIN_MA
#define FW_CFG_SENSE_MIN_MA 20u           /* below this setpoint the sense check is skipped */
#endif
#ifndef FW_CFG_DERATE_PCT
#define FW_CFG_DERATE_PCT 50u             /* current kept between derate and fault temperature */
#endif
#ifndef FW_CFG_SUPPLY_MIN_MV
#define FW_CFG_SUPPLY_MIN_MV 9000u        /* LED supply below this while lit: fault */
#endif
#ifndef FW_CFG_RELEASE_PULSE_US
#define FW_CFG_RELEASE_PULSE_US 100000u   /* camera mode: length of the shutter-release press */
#endif
#ifndef FW_CFG_SAFE_SAMPLE_US
#define FW_CFG_SAFE_SAMPLE_US 10000u      /* temperature and supply sampled this often */
#endif
#ifndef FW_CFG_DEBOUNCE_US
#define FW_CFG_DEBOUNCE_US 20000u         /* button level must hold this long */
#endif
#ifndef FW_CFG_UNLOCK_KEY
#define FW_CFG_UNLOCK_KEY 0xCA1Bu         /* value written to cal_unlock to allow writes */
#endif
#ifndef FW_CFG_UNLOCK_TIMEOUT_US
#define FW_CFG_UNLOCK_TIMEOUT_US 30000000u /* calibration unlock expires after this */
#endif
#ifndef FW_CFG_WDT_MS
#define FW_CFG_WDT_MS 1000u               /* hardware watchdog timeout */
#endif
#ifndef FW_CFG_FW_VERSION
#define FW_CFG_FW_VERSION 0x0100u         /* firmware version, major << 8 | minor */
#endif
#ifndef FW_CFG_FW_VERSION_STR
#define FW_CFG_FW_VERSION_STR "1.0"       /* same, as reported by function 43/14 */
#endif
#ifndef FW_CFG_VENDOR_STR
#define FW_CFG_VENDOR_STR "facette"       /* 43/14 object 0 */
#endif
#ifndef FW_CFG_PRODUCT_STR
#define FW_CFG_PRODUCT_STR "facette-rig"  /* 43/14 object 1 */
#endif
#ifndef FW_CFG_ASSERT_HALT
#define FW_CFG_ASSERT_HALT 1              /* FW_ASSERT halts (debug); 0: ignored */
#endif

#endif /* FACETTE_FW_CONFIG_H */
