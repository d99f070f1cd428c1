# Calls two to four of the sixth Dec 5 session, run on the machine call one left warm (their
# logs: call_two/, call_three/, call_four/). Call one (call_one.sh) timed out its fits and the
# features benchmark on the cold machine's compiles; these gave them more time.
. scripts/gpu_env.sh; export LGS_JAX_CACHE="$PWD/build/jax_cache"; t0=$(date +%s)
case "$1" in
two)  # skull with appearance embeddings; the features' cost per pass
  timeout 230 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
    --app-opt --out /tmp/sa > $out/fit_app.log 2>&1
  echo "fit app rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  cat /tmp/sa/result.json >> $out/times.log
  timeout 150 python3 -m benchmarks.features --data carry/data --scene guitar_x16_1080p \
    --channels 8,32 --repeat 5 > $out/features.log 2>&1
  echo "features rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log ;;
three)  # skull plain and with appearance embeddings, one after the other (warm cache)
  for opt in "" "--app-opt"; do
    timeout 190 python3 -m lgs_jax fit --data carry/data/skull --steps 3000 --eval-every 3000 \
      $opt --out /tmp/w$opt --overwrite > $out/fit$opt.log 2>&1
    echo "fit $opt rc=$? $(( $(date +%s) - t0 )) s" >> $out/times.log
  done ;;
four)  # the relit capture (scripts/relit_capture.py)
  timeout 330 python3 scripts/relit_capture.py --data carry/data --downscale 4 --steps 2000 \
    --modes plain,color_opt,app_opt > $out/relit.log 2> $out/relit.err ;;
esac
cat $out/times.log 2>/dev/null
