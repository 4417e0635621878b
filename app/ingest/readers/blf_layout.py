"""BLF object layout: type numbers, plausibility limits and the status codes of the object walk.

Object layout (little endian; ``hsize`` is 32 for header version 1, 40 for version 2)::

    0   "LOBJ"  u16 header size  u16 header version  u32 object size  u32 object type
    16  u32 object flags (1: timestamp in 10 us units, 2: in ns)
    20  u16 client index / u8 timestamp status     22  u16 object version
    24  u64 timestamp since measurement start        [32 u64 original timestamp: version 2]
    hsize: the object's payload, e.g. CAN_MESSAGE (1) / CAN_MESSAGE2 (86)::

        +0 u16 channel (1-based)  +2 u8 flags (0x01 Tx, 0x80 remote)  +3 u8 DLC
        +4 u32 id (bit 31: extended)  +8 u8[8] data  [CAN_MESSAGE2: +16 u32 frame length, u8 bits, 3 reserved]

    CAN_FD_MESSAGE (100): +0 u16 ch, u8 flags, u8 DLC, u32 id, u32 frame length, u8 arb bits,
        +13 u8 FD flags (1 EDL, 2 BRS, 4 ESI), +14 u8 valid bytes, 5 reserved, +20 u8[64] data
    CAN_FD_MESSAGE_64 (101): +0 u8 ch, u8 DLC, u8 valid bytes, u8 tx count, u32 id, u32 frame length,
        +12 u32 flags (0x10 remote, 0x1000 EDL, 0x2000 BRS, 0x4000 ESI), 4 x u32 bit timing, u16 bits,
        +34 u8 dir, +35 u8 ext data offset, u32 crc, +40 data (may be shorter than "valid": zero-padded)
    CAN_ERROR_EXT (73): +0 u16 ch, u16 length, u32 flags, u8 ecc, u8 position, +10 u8 DLC, 1 reserved,
        u32 frame length, +16 u32 id, u16 ext flags, 2 reserved, +24 u8[8] data
    CAN_ERROR (2): +0 u16 ch, u16 length
    CAN_FD_ERROR_64 (104): +0 u8 ch, u8 DLC, u8 valid bytes, u8 ecc, u16 flags, u16 code ext,
        u16 ext flags, u8 ext data offset, 1 reserved, +12 u32 id, 7 x u32, u16 position, 2 reserved, +44 data

Objects are followed by ``size % 4`` padding bytes; the readers tolerate 0 to 3 bytes of
padding of either convention by looking for the next signature in that window.
"""

# object types (Vector binlog object IDs)
CAN_MESSAGE = 1
CAN_ERROR = 2
LOG_CONTAINER = 10
CAN_ERROR_EXT = 73
CAN_MESSAGE2 = 86
CAN_FD_MESSAGE = 100
CAN_FD_MESSAGE_64 = 101
CAN_FD_ERROR_64 = 104
FRAME_TYPES = frozenset({CAN_MESSAGE, CAN_ERROR, CAN_ERROR_EXT, CAN_MESSAGE2, CAN_FD_MESSAGE,
                         CAN_FD_MESSAGE_64, CAN_FD_ERROR_64})

MAX_OBJECT_SIZE = 1 << 20  # larger inner objects are corrupt sizes (real ones are at most a few kB)

# status codes of the compiled walk (blf_kernel.walk_objects)
ST_END = 0  # every complete object consumed; ``pos`` is the start of an incomplete remainder
ST_FULL = 1  # the output columns are full; ``pos`` is the next object
ST_BAD_SIG = 2  # no "LOBJ" signature at ``pos`` (nor within 3 padding bytes)
ST_BAD_HEADER = 3  # unknown header version or header size; detail = header version
ST_BAD_SIZE = 4  # object size impossible for its type, or the next object is not where it says; detail = size
ST_BAD_TS = 5  # timestamp does not fit int64 ns; detail = object size (skip it)
ST_BAD_FRAME = 6  # a CAN object with impossible content (e.g. > 64 data bytes); detail = object size
