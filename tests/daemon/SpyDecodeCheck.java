// For the lcm_spy scenario: listens on every LCM channel until a stop file appears and decodes
// each message the way lcm-spy does, with lcm-spy's own type database (the classes on the class
// path, looked up by fingerprint) and the class's DataInput constructor. Prints one line per
// channel: CHANNEL TYPE decoded N undecodable M (TYPE "unknown" when no class matched).
//
//   java -cp lcm.jar:jchart2d.jar:slamd-lcmtypes.jar:. SpyDecodeCheck STOP_FILE TIMEOUT_S

import java.io.ByteArrayInputStream;
import java.io.DataInput;
import java.io.DataInputStream;
import java.io.File;
import java.io.IOException;
import java.util.Map;
import java.util.TreeMap;
import lcm.lcm.LCM;
import lcm.lcm.LCMDataInputStream;
import lcm.lcm.LCMSubscriber;
import lcm.spy.LCMTypeDatabase;

public class SpyDecodeCheck implements LCMSubscriber {
  private static class Count {
    String type = "unknown";
    int decoded = 0;
    int undecodable = 0;
  }

  private final Map<String, Count> counts = new TreeMap<>();
  private final LCMTypeDatabase types = new LCMTypeDatabase();

  @Override
  public synchronized void messageReceived(LCM lcm, String channel, LCMDataInputStream in) {
    Count count = counts.computeIfAbsent(channel, name -> new Count());
    try {
      byte[] data = new byte[in.available()];
      in.readFully(data);
      long fingerprint = new DataInputStream(new ByteArrayInputStream(data)).readLong();
      Class<?> type = types.getClassByFingerprint(fingerprint);
      if (type == null) {
        count.undecodable++;
        return;
      }
      type.getConstructor(DataInput.class)
          .newInstance(new DataInputStream(new ByteArrayInputStream(data)));
      count.type = type.getName();
      count.decoded++;
    } catch (IOException | ReflectiveOperationException e) {
      count.undecodable++;
    }
  }

  public static void main(String[] args) throws Exception {
    File stop = new File(args[0]);
    long deadline = System.currentTimeMillis() + (long) (Double.parseDouble(args[1]) * 1000.0);
    SpyDecodeCheck check = new SpyDecodeCheck();
    LCM lcm = LCM.getSingleton();
    lcm.subscribe(".*", check);
    System.out.println("listening");
    System.out.flush();
    while (!stop.exists() && System.currentTimeMillis() < deadline) Thread.sleep(50);
    synchronized (check) {
      for (Map.Entry<String, Count> entry : check.counts.entrySet()) {
        Count count = entry.getValue();
        System.out.println(entry.getKey() + " " + count.type + " decoded " + count.decoded
            + " undecodable " + count.undecodable);
      }
    }
    System.exit(stop.exists() ? 0 : 1);
  }
}
