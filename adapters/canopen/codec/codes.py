"""CANopen code tables with their texts: SDO abort codes, EMCY error codes, the error
register.

CiA 301 §7.2.4.3.17 (SDO abort codes), §7.2.7.1 table "Emergency error codes" and
§7.5.2.2 (error register 0x1001); the drive codes of CiA 402-2 (IEC 61800-7-201)
annex "Error codes" (over current, DC link, temperatures, supplies, motor, following
error).
"""

from __future__ import annotations

# CiA 301 §7.2.4.3.17, table "SDO abort codes".
SDO_ABORT_CODES: dict[int, str] = {
    0x05030000: "toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "client/server command specifier not valid or unknown",
    0x05040002: "invalid block size",
    0x05040003: "invalid sequence number",
    0x05040004: "CRC error",
    0x05040005: "out of memory",
    0x06010000: "unsupported access to an object",
    0x06010001: "attempt to read a write only object",
    0x06010002: "attempt to write a read only object",
    0x06020000: "object does not exist in the object dictionary",
    0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "the number and length of the objects to be mapped would exceed PDO length",
    0x06040043: "general parameter incompatibility reason",
    0x06040047: "general internal incompatibility in the device",
    0x06060000: "access failed due to a hardware error",
    0x06070010: "data type does not match, length of service parameter does not match",
    0x06070012: "data type does not match, length of service parameter too high",
    0x06070013: "data type does not match, length of service parameter too low",
    0x06090011: "sub-index does not exist",
    0x06090030: "value range of parameter exceeded",
    0x06090031: "value of parameter written too high",
    0x06090032: "value of parameter written too low",
    0x06090036: "maximum value is less than minimum value",
    0x060A0023: "resource not available: SDO connection",
    0x08000000: "general error",
    0x08000020: "data cannot be transferred or stored to the application",
    0x08000021: "data cannot be transferred or stored to the application because of local control",
    0x08000022: (
        "data cannot be transferred or stored to the application because of the present "
        "device state"
    ),
    0x08000023: "object dictionary dynamic generation fails or no object dictionary is present",
    0x08000024: "no data available",
}

# The codes this project's SDO client and server abort with.
ABORT_TOGGLE = 0x05030000
ABORT_TIMEOUT = 0x05040000
ABORT_COMMAND = 0x05040001
ABORT_READ_WRITE_ONLY = 0x06010001
ABORT_WRITE_READ_ONLY = 0x06010002
ABORT_NO_OBJECT = 0x06020000
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_LENGTH = 0x06070010
ABORT_NO_SUBINDEX = 0x06090011
ABORT_RANGE = 0x06090030
ABORT_TOO_HIGH = 0x06090031
ABORT_TOO_LOW = 0x06090032
ABORT_GENERAL = 0x08000000
ABORT_DEVICE_STATE = 0x08000022


def abort_text(code: int) -> str:
    """The CiA 301 text of an SDO abort code, 'unknown abort code' for one not in the table."""
    return SDO_ABORT_CODES.get(code, "unknown abort code")


def abort_message(code: int) -> str:
    """``"0x06090030 value range of parameter exceeded"``: the code and its text."""
    return f"0x{code:08X} {abort_text(code)}"


# CiA 301 §7.2.7.1 table "Emergency error codes" (classes), with the CiA 402-2 drive
# codes below them.
EMCY_CODES: dict[int, str] = {
    0x0000: "error reset or no error",
    0x1000: "generic error",
    0x2000: "current",
    0x2100: "current, device input side",
    0x2200: "current inside the device",
    0x2300: "current, device output side",
    0x3000: "voltage",
    0x3100: "mains voltage",
    0x3200: "voltage inside the device",
    0x3300: "output voltage",
    0x4000: "temperature",
    0x4100: "ambient temperature",
    0x4200: "device temperature",
    0x4300: "drive temperature",
    0x5000: "device hardware",
    0x5100: "supply",
    0x5400: "power section",
    0x5500: "data storage",
    0x6000: "device software",
    0x6100: "internal software",
    0x6200: "user software",
    0x6300: "data set",
    0x7000: "additional modules",
    0x7100: "power",
    0x7200: "measurement circuit",
    0x7300: "sensor",
    0x8000: "monitoring",
    0x8100: "communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard error or heartbeat error",
    0x8140: "recovered from bus off",
    0x8150: "CAN-ID collision",
    0x8200: "protocol error",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    0x8240: "unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x8300: "torque control",
    0x8400: "velocity speed controller",
    0x8500: "position controller",
    0x8600: "positioning controller",
    0x8700: "sync controller",
    0x8800: "winding controller",
    0x9000: "external error",
    0xF000: "additional functions",
    0xFF00: "device specific",
    # CiA 402-2 drive codes.
    0x2110: "short circuit/earth leakage (input)",
    0x2120: "earth leakage (input)",
    0x2130: "short circuit (input)",
    0x2210: "continuous over current (device inside)",
    0x2220: "short circuit/earth leakage (device inside)",
    0x2310: "continuous over current",
    0x2311: "continuous over current no. 1",
    0x2312: "continuous over current no. 2",
    0x2320: "short circuit/earth leakage (motor side)",
    0x2330: "earth leakage (motor side)",
    0x2340: "short circuit (motor side)",
    0x3110: "mains over-voltage",
    0x3120: "mains under-voltage",
    0x3130: "phase failure",
    0x3140: "mains frequency",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x3230: "load error",
    0x3310: "output over-voltage",
    0x3320: "armature circuit",
    0x3330: "field circuit",
    0x4110: "excess ambient temperature",
    0x4120: "too low ambient temperature",
    0x4210: "excess temperature device",
    0x4220: "too low temperature device",
    0x4310: "excess temperature drive",
    0x4320: "too low temperature drive",
    0x4400: "supply temperature",
    0x5110: "supply low voltage",
    0x5111: "U1 = supply +/-15 V",
    0x5112: "U2 = supply +24 V",
    0x5113: "U3 = supply +5 V",
    0x5210: "measurement circuit",
    0x5220: "computing circuit",
    0x5410: "output stages",
    0x5420: "chopper",
    0x5430: "input stages",
    0x5440: "contacts",
    0x5510: "working memory",
    0x5520: "program memory",
    0x5530: "non-volatile data memory",
    0x6010: "software reset (watchdog)",
    0x6310: "loss of parameters",
    0x6320: "parameter error",
    0x7110: "brake chopper",
    0x7111: "failure brake chopper",
    0x7112: "over current brake chopper",
    0x7113: "protective circuit brake chopper",
    0x7120: "motor",
    0x7121: "motor blocked",
    0x7122: "motor error or commutation malfunction",
    0x7123: "motor tilted",
    0x7303: "resolver 1 fault",
    0x7304: "resolver 2 fault",
    0x7305: "incremental sensor 1 fault",
    0x7306: "incremental sensor 2 fault",
    0x7310: "speed",
    0x7320: "position",
    0x7500: "communication",
    0x7510: "serial interface no. 1",
    0x7520: "serial interface no. 2",
    0x7600: "data storage (external)",
    0x8311: "excess torque",
    0x8312: "difficult start up",
    0x8313: "standstill torque",
    0x8321: "insufficient torque",
    0x8331: "torque fault",
    0x8401: "velocity following error",
    0x8402: "velocity limit",
    0x8611: "following error",
    0x8612: "reference limit",
    0x9009: "external error (manufacturer)",
}

_CLASS_MASKS = (0xFFF0, 0xFF00, 0xF000)


def emcy_text(code: int) -> str:
    """The text of an EMCY error code: the exact entry, else its class (0xXXX0, 0xXX00,
    0xX000 in turn); 'unknown error code' when none matches."""
    text = EMCY_CODES.get(code)
    if text is not None:
        return text
    for mask in _CLASS_MASKS:
        text = EMCY_CODES.get(code & mask)
        if text is not None and code & mask != 0:
            return text
    return "unknown error code"


# Error register 0x1001 bits (CiA 301 §7.5.2.2).
ERROR_REGISTER = 0x1001
ERROR_REGISTER_BITS: dict[int, str] = {
    0: "generic error",
    1: "current",
    2: "voltage",
    3: "temperature",
    4: "communication error (overrun, error state)",
    5: "device profile specific",
    6: "reserved",
    7: "manufacturer specific",
}


def error_register_texts(register: int) -> tuple[str, ...]:
    """The names of the bits set in an error register value, lowest bit first."""
    return tuple(text for bit, text in ERROR_REGISTER_BITS.items() if register & (1 << bit))
