package iristk.system;

/** Stand-in for IrisTK's IrisUtils: a logger writing to stderr, for compiling Broker.java alone (pairplay test stub). */
public class IrisUtils {
    public static org.slf4j.Logger getLogger(Class<?> owner) {
        return new org.slf4j.Logger() {
            public void info(String message) { System.err.println("INFO " + message); }
            public void error(String message) { System.err.println("ERROR " + message); }
        };
    }
}
