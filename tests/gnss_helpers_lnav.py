"""GPS LNAV test vector: six consecutive L1 C/A subframes (3, 4, 5, 1, 2, 3) of PRN 21, July 2019, as
u-blox RXM-SFRBX words (30-bit words in bits 29..0). Source: the UBLOX_read project's test_eph.cpp
(James Jackson, MIT licence), whose expected decoded values the tests check."""

_FIVE = (
    (0x22C00E31, 0xB04AEBF3, 0x2DD80A, 0x8717A3E7, 0x3FF28987,
     0x2B0C8C8F, 0xAA7F16F, 0x34DE804E, 0xBFE9D329, 0x93BEDA23),
    (0x22C00E31, 0xB04B0CCB, 0x1E67ABC6, 0xB45FFEDF, 0xAF3F61B,
     0xB3EC995, 0xAF8BDBC5, 0xA8658185, 0x815A783F, 0x14586CDC),
    (0x22C00E31, 0xB04B2D43, 0x1182E14B, 0x9057592, 0xBF518007,
     0x2843254D, 0x975FA428, 0x3506DBE1, 0x92868A6E, 0xBFFFEE80),
    (0x22C00E31, 0xB04B4947, 0xE40028, 0x16FCCA86, 0x9A781ADA,
     0x8EE9581B, 0x3813FAAA, 0x93A4798D, 0x80000F52, 0xBB0CF018),
    (0x22C00E31, 0xB04B6A2F, 0x13BF545B, 0xD8FD7B7, 0xA602FE6,
     0xBF52C317, 0x232EFAFD, 0x80D3A86D, 0x83658D1C, 0x24799FE3),
)
# the sixth is the next subframe 3: the first one's data under a later hand-over word
SUBFRAMES_PRN21 = (*_FIVE, (_FIVE[0][0], 0xB04B8B13, *_FIVE[0][2:]))
