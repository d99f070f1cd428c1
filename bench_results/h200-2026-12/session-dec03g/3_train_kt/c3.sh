# call 3: training with the lean forward on by default (lego 200x200, 7k steps, no gsplat),
# then every kernel of the synthetic scenes' forward + backward, ours and gsplat's
. scripts/gpu_env.sh
TRAIN_TIMEOUT=230 TRAIN_SCENES=lego bash scripts/scale_gpu_check.sh train > $out/train_summary.txt 2>&1
SCENE_TIMEOUT=120 SCENES="synthetic10M_4k synthetic4M_1080p" \
  KT_ARGS="--grad --rows localgs --iters 5 --top 40" bash scripts/scale_gpu_check.sh kernels > $out/kt_summary.txt 2>&1
cat $out/train_summary.txt $out/kt_summary.txt
tar czf /tmp/all.tgz -C $OUT . && rm -rf $OUT/* && mv /tmp/all.tgz $OUT/
