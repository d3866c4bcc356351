import json, math, os, subprocess
from common import WORK, POINTLENS, BENCH
REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', '..')
G=96
D=dict(bunny=f'{REPO}/data/bunny_colored.ply', mug=f'{REPO}/data/pcl_table_scene_mug_rgb.ply', autzen=f'{REPO}/data/autzen_trim.las')
for S,d in D.items():
    c=json.load(open(f'{BENCH}/{S}/camera.json'))
    H=c['height']; W=c['width']
    c['fovy_deg']=math.degrees(2*math.atan(math.tan(math.radians(c['fovy_deg'])/2)*(H+2*G)/H))
    c['width']=W+2*G; c['height']=H+2*G
    json.dump(c,open(f'{WORK}/{S}_cam_ext.json','w'),indent=1)
    subprocess.run([POINTLENS,'-q','render',d,'-o',f'{WORK}/{S}_ext.exr','--camera',f'{WORK}/{S}_cam_ext.json','--method','pinhole','--passes','z,coc','--ssaa','3'],check=True)
