"""Mean angle (degrees) between the normals of edge-adjacent faces of OBJ meshes, the
normals being the faces' vector areas: `voxreg_quality::mean_adjacent_angle_deg`'s
definition, for outputs of any options.

    python3 bench/mean_angle.py out.obj [more.obj ...]
"""
import sys, numpy as np
def load(p):
    V=[];F=[]
    for l in open(p):
        if l.startswith('v '): V.append([float(x) for x in l.split()[1:4]])
        elif l.startswith('f '): F.append([int(x.split('/')[0])-1 for x in l.split()[1:]])
    return np.array(V),F
def adjacent_pairs(F):
    """The pairs of faces sharing an edge that no other face shares."""
    E={}
    for fi,f in enumerate(F):
        for i in range(len(f)):
            e=tuple(sorted((f[i],f[(i+1)%len(f)]))); E.setdefault(e,[]).append(fi)
    return [fs for fs in E.values() if len(fs)==2]
def mean_angle(V,F):
    N=[]
    for f in F:
        p=V[f]; n=np.zeros(3)
        for i in range(len(f)): n+=np.cross(p[i],p[(i+1)%len(f)])
        N.append(n/ (np.linalg.norm(n)+1e-300))
    N=np.array(N)
    a=[np.degrees(np.arccos(np.clip(np.dot(N[f],N[g]),-1,1))) for f,g in adjacent_pairs(F)]
    return np.mean(a)
if __name__ == "__main__":
    for p in sys.argv[1:]:
        V,F=load(p); print(p, round(mean_angle(V,F),2))
