#!/usr/bin/env python3
"""Makes brick_patch.png: a texture-patch mask for data/textures/brick.png
whose outline follows the grout (Praun et al. 2000 §3.1: "the texture patch
boundaries should ... follow the grout"): whole bricks around the centre, cut
along the vertical mortar lines and, per column of bricks, along the
horizontal ones. White = inside. Pure Python (zlib only):

    python3 configs/masks/brick_patch.py
"""
import os, statistics, struct, zlib
HERE = os.path.dirname(os.path.abspath(__file__))
def read_png(path):
    data = open(path,'rb').read()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    pos = 8; idat = b''; w=h=None
    while pos < len(data):
        n, = struct.unpack('>I', data[pos:pos+4]); t = data[pos+4:pos+8]; c = data[pos+8:pos+8+n]; pos += 12+n
        if t == b'IHDR':
            w,h,bd,ct,_,_,il = struct.unpack('>IIBBBBB', c); assert bd==8 and il==0; ch={0:1,2:3,4:2,6:4}[ct]
        elif t == b'IDAT': idat += c
    raw = zlib.decompress(idat); stride = w*ch; out = []; prev = bytearray(stride); i = 0
    for y in range(h):
        f = raw[i]; i += 1; line = bytearray(raw[i:i+stride]); i += stride
        for x in range(stride):
            a = line[x-ch] if x >= ch else 0; b = prev[x]; c = prev[x-ch] if x >= ch else 0
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + b) & 255
            elif f == 3: line[x] = (line[x] + (a + b)//2) & 255
            elif f == 4:
                p = a + b - c; pa, pb, pc = abs(p-a), abs(p-b), abs(p-c)
                pr = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[x] = (line[x] + pr) & 255
        out.append(bytes(line)); prev = line
    return w, h, ch, out
def write_png_grey(path, w, h, rows):
    raw = b''.join(b'\x00' + bytes(r) for r in rows)
    def chunk(t, c): return struct.pack('>I', len(c)) + t + c + struct.pack('>I', zlib.crc32(t + c) & 0xffffffff)
    open(path,'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 0, 0, 0, 0)) + chunk(b'IDAT', zlib.compress(raw, 9)) + chunk(b'IEND', b''))
# Builds a texture-patch mask for brick.png whose outline follows the grout
# (Praun et al. 2000 §3.1): whole bricks around the centre, cut along the
# vertical and horizontal mortar lines.
w,h,ch,rows = read_png(os.path.join(HERE, '../../data/textures/brick.png'))
L = [[sum(r[x*ch:x*ch+3])/3.0 for x in range(w)] for r in rows]
# Vertical grout: columns whose mean brightness is a local maximum well above the rest.
col = [sum(L[y][x] for y in range(h))/h for x in range(w)]
cm = statistics.median(col)
vx = [x for x in range(w) if col[x] > cm + 12 and col[x] >= col[(x-1)%w] and col[x] >= col[(x+1)%w]]
print('column means median', cm, 'vertical grout at', vx, [round(col[x]) for x in vx])
lines = [11, 28, 45, 63, 82, 99, 118]
cols = list(zip(lines, lines[1:] + [lines[0] + w]))
grout_rows = {}
for (a, b) in cols:
    xs = [x % w for x in range(a + 3, b - 2)]
    prof = [sum(L[y][x] for x in xs)/len(xs) for y in range(h)]
    med = statistics.median(prof)
    peaks = [y for y in range(h) if prof[y] > med + 20 and prof[y] >= prof[(y-1)%h] and prof[y] >= prof[(y+1)%h]]
    grout_rows[(a,b)] = peaks
    print((a,b), 'median', round(med), 'rows', peaks, [round(prof[y]) for y in peaks])
mask = [[0]*w for _ in range(h)]
for (a, b) in cols:
    if b >= w:
        continue
    rs = [y for y in grout_rows[(a, b)] if 1 <= y <= 120]
    top, bottom = rs[0], rs[-1]
    if bottom - top < 40:
        continue
    for y in range(top, bottom + 1):
        for x in range(a, b + 1):
            mask[y][x] = 255
    print('column', (a, b), 'rows', top, bottom)
write_png_grey(os.path.join(HERE, 'brick_patch.png'), w, h, mask)
for y in range(0, h, 4):
    print(''.join('#' if mask[y][x] else '.' for x in range(0, w, 2)))
