"""Structural check of an MDF 4 file before asammdf parses it.

asammdf reads channel records in compiled code that trusts the file: a damaged byte offset,
bit count, cycle count or block link can make it read outside its buffers (the process dies
with a segmentation fault) or loop forever. This module walks the block graph of the file
with bounds and cycle checks and verifies that every channel fits in its record and every
record in its data, so that a damaged file gives a :class:`~clutchlab.errors.DataError`
instead. It checks structure only, not values.

Layout references: ASAM MDF 4.x block headers (``##XX``, reserved, length, link count,
links), DG / CG / CN / DT / DZ / DL / HL fields.
"""

from __future__ import annotations

import math
import mmap
import struct
from pathlib import Path

from ..errors import DataError

__all__ = ["check_mdf4_structure"]

_HEADER = struct.Struct("<4s4xQQ")  # id, length, link count
_MAX_BLOCKS = 1_000_000
#: Chains followed through link 0 ("next") — a cycle there makes readers loop forever.
_CHAINED = {b"##DG", b"##CG", b"##CN", b"##AT", b"##FH", b"##EV", b"##CH", b"##DL", b"##SR"}
#: Bits a channel of each data type may occupy (None: any multiple of 8).
_DATA_TYPE_BITS: dict[int, tuple[int, ...] | None] = {
    **{t: tuple(range(1, 65)) for t in range(4)},  # unsigned / signed integers, LE / BE
    4: (16, 32, 64),
    5: (16, 32, 64),  # floats LE / BE
    **{t: None for t in range(6, 13)},  # strings, byte array, MIME sample / stream
    13: (56,),  # CANopen date
    14: (48,),  # CANopen time
    15: (32, 64, 128),
    16: (32, 64, 128),  # complex LE / BE
}


class _File:
    def __init__(self, data: bytes | mmap.mmap, path: Path) -> None:
        self.data = data
        self.path = path
        self.size = len(data)

    def fail(self, what: str) -> DataError:
        return DataError(f"{self.path}: damaged MDF file (refused before parsing): {what}")

    def block(self, addr: int, where: str) -> tuple[bytes, list[int], int]:
        """(id, links, offset of the data section) of the block at ``addr``."""
        if addr < 64:
            raise self.fail(f"{where} points outside the file (address {addr})")
        if addr + 24 > self.size:
            raise self.fail(
                f"{where} points beyond the end of the file (address {addr}, file "
                f"{self.size} bytes: truncated?)"
            )
        bid, length, nlinks = _HEADER.unpack_from(self.data, addr)
        if bid[:2] != b"##":
            raise self.fail(f"{where} does not point to a block (address {addr})")
        if length < 24 + 8 * nlinks:
            raise self.fail(f"block {bid.decode(errors='replace')} at {addr} has a bad length")
        if addr + length > self.size:
            raise self.fail(
                f"block {bid.decode(errors='replace')} at {addr} ends beyond the end of the "
                f"file ({addr + length} > {self.size} bytes: truncated?)"
            )
        links = list(struct.unpack_from(f"<{nlinks}Q", self.data, addr + 24))
        return bid, links, addr + 24 + 8 * nlinks

    def block_end(self, addr: int) -> int:
        return addr + _HEADER.unpack_from(self.data, addr)[1]


def _walk_links(f: _File, root: int) -> None:
    """Every block reachable from ``root`` lies inside the file; no chain loops."""
    seen: set[int] = set()
    stack = [(root, "header")]
    while stack:
        addr, where = stack.pop()
        if addr in seen:
            continue
        seen.add(addr)
        if len(seen) > _MAX_BLOCKS:
            raise f.fail("too many blocks")
        bid, links, _ = f.block(addr, where)
        name = bid.decode(errors="replace")
        if bid in _CHAINED and links:  # follow the "next" chain here, checking for a loop
            chain, nxt = {addr}, links[0]
            while nxt:
                if nxt in chain:
                    raise f.fail(f"the {name} chain loops back to address {nxt}")
                chain.add(nxt)
                nbid, nlinks, _ = f.block(nxt, f"{name} next link")
                if nbid != bid:
                    raise f.fail(f"the {name} chain continues with a {nbid.decode('latin-1')}")
                nxt = nlinks[0] if nlinks else 0
        stack.extend((link, f"a link of {name} at {addr}") for link in links if link)


def _data_length(f: _File, addr: int, depth: int = 0) -> int:
    """Bytes of record data held by the data block (list) at ``addr``."""
    if not addr:
        return 0
    bid, links, data = f.block(addr, "a data link")
    if bid in (b"##DT", b"##DV", b"##RD", b"##SD"):
        return f.block_end(addr) - data
    if bid == b"##DZ":
        if data + 24 > f.block_end(addr):
            raise f.fail(f"DZ block at {addr} is too short")
        org_length, zipped = struct.unpack_from("<QQ", f.data, data + 8)
        if data + 24 + zipped > f.block_end(addr):
            raise f.fail(f"DZ block at {addr} claims more data than it holds")
        return org_length
    if bid == b"##HL" and depth < 2:
        return _data_length(f, links[0] if links else 0, depth + 1)
    if bid == b"##DL" and depth < 3:
        total, seen, nxt = 0, set(), addr
        while nxt:
            if nxt in seen:
                raise f.fail(f"the DL chain at {addr} loops")
            seen.add(nxt)
            _, dl_links, _ = f.block(nxt, "a DL link")
            total += sum(_data_length(f, a, depth + 1) for a in dl_links[1:] if a)
            nxt = dl_links[0] if dl_links else 0
        return total
    raise f.fail(f"unsupported data block {bid.decode(errors='replace')} at {addr}")


def _check_channel_group(f: _File, cg_addr: int, id_size: int) -> tuple[int, int]:
    """(bytes of one record, number of records) of a channel group; channels checked."""
    _, links, data = f.block(cg_addr, "a CG link")
    if data + 32 > f.block_end(cg_addr):
        raise f.fail(f"CG block at {cg_addr} is too short")
    _, cycles, flags, _, _, data_bytes, inval_bytes = struct.unpack_from("<QQHHIII", f.data, data)
    if flags & 1:  # VLSD channel group: variable-length records, nothing to lay out
        return 0, 0
    record_bits = 8 * data_bytes
    cn_addr, count = links[1] if len(links) > 1 else 0, 0
    while cn_addr:
        count += 1
        if count > 100_000:
            raise f.fail(f"CG block at {cg_addr} has too many channels")
        _, cn_links, cn = f.block(cn_addr, "a CN link")
        if cn + 24 > f.block_end(cn_addr):
            raise f.fail(f"CN block at {cn_addr} is too short")
        cn_type, _, data_type, bit_offset, byte_offset, bit_count, cn_flags, inval_pos = (
            struct.unpack_from("<BBBBIIII", f.data, cn)
        )
        where = f"channel at {cn_addr}"
        if data_type not in _DATA_TYPE_BITS:
            raise f.fail(f"{where}: unknown data type {data_type}")
        if cn_type in (0, 2, 4, 5):  # stored in the record
            allowed = _DATA_TYPE_BITS[data_type]
            if (allowed is None and (bit_count % 8 or bit_count == 0)) or (
                allowed is not None and bit_count not in allowed
            ):
                raise f.fail(f"{where}: {bit_count} bits for data type {data_type}")
            end_bits = 8 * byte_offset + bit_offset + bit_count
            if end_bits > record_bits:
                raise f.fail(
                    f"{where}: bytes {byte_offset}..{math.ceil(end_bits / 8)} outside the "
                    f"{data_bytes}-byte record"
                )
        elif cn_type == 1 and 8 * byte_offset + 64 > record_bits:  # VLSD offset
            raise f.fail(f"{where}: the VLSD offset lies outside the record")
        if cn_flags & 0b10 and inval_pos >= 8 * inval_bytes:
            raise f.fail(f"{where}: invalidation bit {inval_pos} outside the record")
        cn_addr = cn_links[0] if cn_links else 0
    return id_size + data_bytes + inval_bytes, cycles


def check_mdf4_structure(path: str | Path) -> None:
    """Refuse an MDF 4 file whose structure would make a reader leave its buffers.

    Parameters
    ----------
    path : path-like
        The file.

    Raises
    ------
    DataError
        Naming the file: not MDF 4, a block or link outside the file, a looping chain, a
        channel outside its record, records beyond the stored data, an unknown data type.
    """
    path = Path(path)
    with path.open("rb") as fh:
        head = fh.read(64)
        if len(head) < 64 or head[:8] != b"MDF     ":
            raise DataError(f"{path}: not an MDF file (no 'MDF' identification block)")
        version = head[8:16].decode("latin-1").strip()
        if not version.startswith("4."):
            raise DataError(f"{path}: MDF version {version!r} is not supported (MDF 4.x only)")
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
            try:
                _check(_File(data, path))
            except DataError:  # a ValueError too: already names the file, keep it as is
                raise
            except (struct.error, IndexError, ValueError, OverflowError) as exc:
                raise DataError(
                    f"{path}: damaged MDF file (refused before parsing): {exc}"
                ) from None


def _check(f: _File) -> None:
    if f.size < 64 + 24:
        raise f.fail("no header block")
    bid, hd_links, _ = f.block(64, "the identification block")
    if bid != b"##HD":
        raise f.fail("no header block at address 64")
    _walk_links(f, 64)
    dg_addr = hd_links[0] if hd_links else 0
    while dg_addr:
        _, dg_links, dg = f.block(dg_addr, "a DG link")
        id_size = f.data[dg] if dg < f.block_end(dg_addr) else 0
        if id_size not in (0, 1, 2, 4, 8):
            raise f.fail(f"DG block at {dg_addr}: record id size {id_size}")
        groups = []
        cg_addr = dg_links[1] if len(dg_links) > 1 else 0
        while cg_addr:
            groups.append(_check_channel_group(f, cg_addr, id_size))
            cg_links = f.block(cg_addr, "a CG link")[1]
            cg_addr = cg_links[0] if cg_links else 0
        needed = sum(size * cycles for size, cycles in groups)
        if len(groups) > 1 and id_size == 0:
            raise f.fail(f"DG block at {dg_addr}: several channel groups without record ids")
        available = _data_length(f, dg_links[2] if len(dg_links) > 2 else 0)
        if needed > available:
            raise f.fail(
                f"DG block at {dg_addr}: {needed} bytes of records but {available} bytes of data"
            )
        dg_addr = dg_links[0] if dg_links else 0
