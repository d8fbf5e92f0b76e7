"""Rebuilds docs/images/pickcube-robots.png, the README's picture: PickCube-v1 with each robot
at the end of its scripted solver's first episode, side by side at half size. Standard library
only. Run from the repository root after `cargo build --release`:

    for r in panda fetch xarm6_robotiq so100 widowxai; do
        target/release/mjskill rollout --robot $r --episodes 1 --out /tmp/$r.mcap
    done
    python3 docs/images/montage.py docs/images/pickcube-robots.png \
        /tmp/panda.png /tmp/fetch.png /tmp/xarm6_robotiq.png /tmp/so100.png /tmp/widowxai.png

docs/images/tasks-panda.png, every task, the same way (PushT at its seeded first state;
PegInsertionSide with its robot, the panda_wristcam):

    for e in PickCube-v1 PokeCube-v1 PlaceSphere-v1 PushCube-v1 PullCube-v1 StackCube-v1 \
             LiftPegUpright-v1; do
        target/release/mjskill rollout --env $e --robot panda --episodes 1 --out /tmp/$e.mcap
    done
    target/release/mjskill rollout --env PegInsertionSide-v1 --episodes 1 \
        --out /tmp/PegInsertionSide-v1.mcap
    target/release/mjskill render --env PushT-v1 --seed 0 -o /tmp/PushT-v1.png
    python3 docs/images/montage.py docs/images/tasks-panda.png /tmp/PickCube-v1.png \
        /tmp/PokeCube-v1.png /tmp/PlaceSphere-v1.png /tmp/PushCube-v1.png /tmp/PullCube-v1.png \
        /tmp/StackCube-v1.png /tmp/LiftPegUpright-v1.png /tmp/PushT-v1.png \
        /tmp/PegInsertionSide-v1.png
"""
import zlib, struct, sys
def read_png(path):
    data=open(path,'rb').read(); assert data[:8]==b'\x89PNG\r\n\x1a\n'
    i=8; idat=b''; w=h=None
    while i<len(data):
        n=struct.unpack('>I',data[i:i+4])[0]; t=data[i+4:i+8]; c=data[i+8:i+8+n]; i+=12+n
        if t==b'IHDR':
            w,h,bd,ct,_,_,il=struct.unpack('>IIBBBBB',c); assert bd==8 and il==0
            bpp={2:3,6:4,0:1}[ct]
        elif t==b'IDAT': idat+=c
    raw=zlib.decompress(idat); stride=w*bpp; rows=[]; prev=bytearray(stride); p=0
    for y in range(h):
        f=raw[p]; line=bytearray(raw[p+1:p+1+stride]); p+=1+stride
        if f==1:
            for x in range(bpp,stride): line[x]=(line[x]+line[x-bpp])&255
        elif f==2:
            for x in range(stride): line[x]=(line[x]+prev[x])&255
        elif f==3:
            for x in range(stride): line[x]=(line[x]+((line[x-bpp] if x>=bpp else 0)+prev[x])//2)&255
        elif f==4:
            for x in range(stride):
                a=line[x-bpp] if x>=bpp else 0; b=prev[x]; c=prev[x-bpp] if x>=bpp else 0
                pa,pb,pc=abs(b-c),abs(a-c),abs(a+b-2*c)
                pr=a if pa<=pb and pa<=pc else (b if pb<=pc else c)
                line[x]=(line[x]+pr)&255
        rows.append(bytes(line) if bpp==3 else bytes(v for k in range(w) for v in line[k*bpp:k*bpp+3])); prev=line
    return w,h,rows
def write_png(path,w,h,rows):
    raw=b''.join(b'\x00'+r for r in rows)
    def chunk(t,c): return struct.pack('>I',len(c))+t+c+struct.pack('>I',zlib.crc32(t+c)&0xffffffff)
    open(path,'wb').write(b'\x89PNG\r\n\x1a\n'+chunk(b'IHDR',struct.pack('>IIBBBBB',w,h,8,2,0,0,0))+chunk(b'IDAT',zlib.compress(raw,9))+chunk(b'IEND',b''))
files = sys.argv[2:]  # halved by a 2x2 box filter
imgs=[read_png(f) for f in files]
W = sum(w // 2 for w, h, _ in imgs); H = imgs[0][1] // 2
out=[bytearray() for _ in range(H)]
for w,h,rows in imgs:
    for y in range(H):
        r0=rows[2*y]; r1=rows[2*y+1]
        for x in range(w//2):
            for ch in range(3):
                s=r0[6*x+ch]+r0[6*x+3+ch]+r1[6*x+ch]+r1[6*x+3+ch]
                out[y].append((s+2)//4)
write_png(sys.argv[1],W,H,[bytes(r) for r in out])
